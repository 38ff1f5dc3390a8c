"""``gyroemu allan`` results people can trust: the static check, terms reported with their interval or
as not resolved, the accelerometer beside the gyro, plots in the format named, Kalibr's imu.yaml and
the JSON report.

Logs are short (``consumer_mems`` at 1 kHz, 60 s static, 20 s of manoeuvre) to keep the suite fast.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import warnings

import numpy as np
import pytest
from cli_runs import run_cli

from gyroemu.pipelines.formats import atomic
from gyroemu.pipelines.formats.mcap_log import read_mcap
from gyroemu.pipelines.jobs.allan import (
    AllanLogError,
    AllanMotionError,
    MotionWarning,
    allan_of_log,
    allan_report,
)
from gyroemu.pipelines.jobs.simulate import SimulateOptions, run_simulate
from gyroemu.sensors.allan import allan_deviation, fit_allan
from gyroemu.sensors.noise import flicker_noise, white_noise


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("trust")
    out = {}
    for name, scenario, duration in (("static", "bench_static", 60.0), ("moving", "smooth_manoeuvre", 20.0)):
        out[name] = folder / f"{name}.mcap"
        run_simulate(
            SimulateOptions(scenario=scenario, device="consumer_mems", duration=duration, out=out[name], progress=False)
        )
    return out


def run(*args):
    """``gyroemu allan ARGS`` in this process: (exit status, stdout, stderr)."""
    return run_cli(["allan", *map(str, args)])


def test_a_static_log_passes_the_static_check(logs):
    report = allan_of_log(logs["static"])
    check = report.static
    assert check is not None and check.static, check
    names = {f.name for f in check.figures}
    assert names == {"accel_magnitude", "accel_direction", "truth_rate", "truth_attitude"}
    assert check.moving() == ""


def test_a_moving_log_is_refused_naming_the_figure_unless_motion_is_allowed(logs):
    with pytest.raises(AllanMotionError, match=r"the accelerometer's direction moves by [\d.]+ deg \(static: < "):
        allan_of_log(logs["moving"])
    status, _, err = run(logs["moving"], "--out", logs["moving"].with_suffix(".png"))
    assert status == 2
    assert "not a static log" in err and "the true attitude turns by" in err and "--allow-motion" in err
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        report = allan_of_log(logs["moving"], allow_motion=True)
    assert any(issubclass(w.category, MotionWarning) for w in caught)
    assert not report.static.static


def test_a_spin_that_saturates_an_axis_is_refused_as_motion(tmp_path):
    """A heavy top's 150 rad/s spin holds consumer_mems's z at its range: a constant axis, whose σ(τ) is 0.
    The log is refused as moving, naming the figures with a threshold from the axes that have noise
    (it ended in 'array must not contain infs or NaNs', from fitting the constant axis first); with
    --allow-motion the constant axis's terms are 0."""
    log = tmp_path / "spin.mcap"
    run_simulate(SimulateOptions(scenario="heavy_top", device="consumer_mems", duration=10.0, out=log, progress=False))
    with pytest.raises(AllanMotionError, match=r"the true rate moves by [\d.]+ deg/s \(static: < 0\.\d*[1-9]"):
        allan_of_log(log)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MotionWarning)
        report = allan_of_log(log, allow_motion=True)
    assert report.fits[2].arw.value == 0.0 and report.fits[2].arw.high == 0.0
    assert report.fits[0].arw.value > 0.0


def test_random_walk_of_a_short_white_and_bias_instability_run_is_not_resolved():
    """10 min at 100 Hz of white noise and bias instability only: no random walk to resolve."""
    dt, n = 0.01, 60_000
    rng = np.random.default_rng(7)
    gyro = white_noise(rng, (n, 3), dt, 1e-3) + flicker_noise(rng, (n, 3), dt, 2e-4, (0.01, 1e4))
    for axis in range(3):
        fit = fit_allan(allan_deviation(gyro[:, axis], dt))
        assert not fit.rrw.resolved, fit.rrw
        assert fit.rrw.upper_limit > 0
        assert fit.arw.resolved and fit.arw.low < fit.arw.value < fit.arw.high
        assert fit.arw.value == pytest.approx(1e-3, rel=0.05)
    rows = {line.split()[0]: line for line in allan_report(gyro, dt).table().splitlines()[1:]}
    assert rows["rrw"].count("not resolved (< ") == 3
    assert len(re.findall(r"\d\.\d+ \(\d\.\d+–\d\.\d+\)", rows["arw"])) == 3


def test_the_accelerometer_is_analysed_as_the_in_memory_path_does(logs):
    report = allan_of_log(logs["static"])
    samples = read_mcap(logs["static"]).device.samples
    dt = float(np.median(np.diff(samples.t)))
    reference = allan_report(samples.gyro, dt, report.spec, accel=samples.accel, accel_spec=report.accel_spec)
    assert report.accel_fits is not None and reference.accel_fits is not None
    for ours, ref in zip(report.accel_fits, reference.accel_fits):
        np.testing.assert_allclose(ours.allan.adev, ref.allan.adev, rtol=1e-9)
    assert report.table("accel") == reference.table("accel")
    vrw = report.accel_spec.noise_density[0] * 60.0  # m/s/√h
    assert all(f.arw.low * 60.0 < vrw * 1.05 and f.arw.high * 60.0 > vrw * 0.95 for f in report.accel_fits)


def test_tables_plots_in_the_named_formats_and_kalibr_yaml(logs, tmp_path):
    pdf, svg, yaml = tmp_path / "a.pdf", tmp_path / "a.svg", tmp_path / "imu.yaml"
    status, out, err = run(logs["static"], "--out", pdf, "--kalibr", yaml)
    assert status == 0, err
    assert "gyro term" in out and "accel term" in out
    accel_rows = {line.split()[0] for line in out.split("accel term", 1)[1].splitlines()[1:]}
    assert {"vrw", "bias_instability", "random_walk"} <= accel_rows
    assert pdf.read_bytes().startswith(b"%PDF")

    fields = {}
    for line in yaml.read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            key, value = line.split("#", 1)[0].split(":", 1)
            fields[key.strip()] = value.strip()
    assert set(fields) == {
        "accelerometer_noise_density",
        "accelerometer_random_walk",
        "gyroscope_noise_density",
        "gyroscope_random_walk",
        "rostopic",
        "update_rate",
    }
    report = allan_of_log(logs["static"])
    arw = max(f.arw.value for f in report.fits)  # rad/√s = rad/s/√Hz
    assert float(fields["gyroscope_noise_density"]) == pytest.approx(arw, rel=1e-6)
    assert float(fields["update_rate"]) == pytest.approx(1000.0)
    assert fields["rostopic"] == "/imu"
    if not all(f.rrw.resolved for f in report.fits):
        assert "upper limit: not resolved" in yaml.read_text()

    before = yaml.read_text()
    status, _, err = run(logs["static"], "--out", svg, "--kalibr", yaml)
    assert status == 2 and "--force" in err and not svg.exists()
    status, _, err = run(logs["static"], "--out", svg, "--kalibr", yaml, "--force")
    assert status == 0, err
    assert yaml.read_text() == before
    head = svg.read_bytes()[:200].lstrip()
    assert head.startswith(b"<?xml") or head.startswith(b"<svg")


def test_an_unknown_plot_suffix_is_refused_before_any_work(tmp_path):
    status, _, err = run(tmp_path / "missing.mcap", "--out", tmp_path / "plot.xyz")
    assert status == 2
    assert "argument --out" in err and ".xyz" in err and "missing.mcap" not in err.split("argument --out")[0]
    assert not (tmp_path / "plot.xyz").exists()


def test_json_report(logs, tmp_path):
    status, out, err = run(logs["static"], "--json", "--out", tmp_path / "a.png")
    assert status == 0, err
    data = json.loads(out)
    for sensor in ("gyro", "accel"):
        for term in ("quantisation", "arw", "bias_instability", "rrw", "rate_ramp"):
            entry = data[sensor][term]
            assert entry["unit"]
            for axis in "xyz":
                assert set(entry[axis]) == {"value", "low", "high", "resolved", "upper_limit"}
    assert data["gyro"]["arw"]["x"]["resolved"] is True
    check = data["static_check"]
    assert check["static"] is True
    assert set(check["figures"]["accel_direction"]) == {"value", "limit", "unit", "static"}
    assert "Allan plot" in err


def test_no_plot_draws_none_and_checks_none_so_a_script_may_run_twice(logs, tmp_path):
    """``--json --no-plot`` run twice on one log: no picture written, none checked (an earlier plot at the
    default path stays as it was, without --force); the same report both times; --kalibr still written
    and still refused without --force; with --out it is refused before any work."""
    log = tmp_path / "static.mcap"
    os.symlink(logs["static"], log)
    earlier = tmp_path / "static.allan.png"
    earlier.write_bytes(b"an earlier plot")
    reports = []
    for _ in range(2):
        status, out, err = run(log, "--json", "--no-plot")
        assert status == 0, err
        assert "Allan plot" not in err
        reports.append(json.loads(out))
    assert reports[0] == reports[1]
    assert earlier.read_bytes() == b"an earlier plot"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["static.allan.png", "static.mcap"]
    kalibr = tmp_path / "imu.yaml"
    assert run(log, "--no-plot", "--kalibr", kalibr)[0] == 0 and kalibr.read_text().startswith("# IMU noise")
    status, _, err = run(log, "--no-plot", "--kalibr", kalibr)
    assert status == 2 and f"argument --kalibr: {kalibr} exists (use --force" in one_error_line(err)
    status, _, err = run(log, "--no-plot", "--out", tmp_path / "x.png")
    assert status == 2 and "argument --out: not allowed with argument --no-plot" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["imu.yaml", "static.allan.png", "static.mcap"]


def test_check_options_without_a_plot_checks_none_and_refuses_an_out(tmp_path):
    from gyroemu.pipelines.jobs.allan import AllanError, check_options

    log = tmp_path / "static.mcap"
    log.write_bytes(b"a log")
    (tmp_path / "static.allan.png").write_bytes(b"an earlier plot")
    assert check_options(log, plot=False) is None
    with pytest.raises(AllanError, match="static.allan.png exists"):
        check_options(log)
    with pytest.raises(AllanError, match="argument --no-plot: draws no plot, but --out names one"):
        check_options(log, tmp_path / "x.png", plot=False)


def one_error_line(err: str) -> str:
    """The one line ``gyroemu allan`` printed for bad input (no traceback)."""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gyroemu allan: error: "), err
    return lines[0]


def test_an_output_that_is_the_log_is_refused_even_with_force(logs, tmp_path):
    log = tmp_path / "s2.mcap"
    shutil.copyfile(logs["static"], log)
    before = log.read_bytes()
    (tmp_path / "sub").mkdir()
    os.symlink(log, tmp_path / "link.png")
    os.link(log, tmp_path / "hard.yaml")
    for args in (
        ["--kalibr", log, "--force"],
        ["--kalibr", tmp_path / "sub" / ".." / "s2.mcap", "--force"],
        ["--kalibr", tmp_path / "hard.yaml", "--force"],
        ["--out", tmp_path / "link.png", "--force"],
    ):
        status, _, err = run(log, *args)
        assert status == 2, (args, err)
        line = one_error_line(err)
        assert f"{args[0]}: " in line and "is an input" in line and "never overwritten, even with --force" in line
        assert log.read_bytes() == before
        assert not (tmp_path / "s2.allan.png").exists()
    status, _, err = run(log, "--out", tmp_path / "a.png", "--kalibr", tmp_path / "sub" / ".." / "a.png")
    assert status == 2 and "argument --kalibr" in one_error_line(err) and "plot" in err
    assert not (tmp_path / "a.png").exists()


def test_an_existing_plot_is_refused_without_force_as_kalibr_is(logs, tmp_path):
    log = tmp_path / "static.mcap"
    os.symlink(logs["static"], log)
    default, named = tmp_path / "static.allan.png", tmp_path / "x.png"
    for plot, args in ((default, []), (named, ["--out", named])):
        plot.write_text("u\n")
        status, _, err = run(log, *args)
        assert status == 2, err
        line = one_error_line(err)
        assert "argument --out" in line and f"{plot.name} exists" in line and "--force" in line
        assert plot.read_text() == "u\n"
    status, _, err = run(log, "--out", named, "--force")
    assert status == 0, err
    assert named.read_bytes().startswith(b"\x89PNG")


def test_an_output_in_a_missing_folder_is_refused_before_any_work(logs, tmp_path):
    plot = tmp_path / "a.png"
    (tmp_path / "afile").write_text("")
    for args, argument in (
        (["--out", tmp_path / "nodir" / "x.png"], "--out"),
        (["--out", plot, "--kalibr", tmp_path / "nodir" / "k.yaml"], "--kalibr"),
        (["--out", plot, "--kalibr", tmp_path / "afile" / "k.yaml"], "--kalibr"),
    ):
        status, _, err = run(logs["static"], *args)
        assert status == 2, err
        line = one_error_line(err)
        assert f"argument {argument}:" in line and ("no such folder" in line or "not a folder" in line), line
        assert not plot.exists()


def test_a_folder_named_as_an_output_file_is_refused_as_a_folder(logs, tmp_path):
    (tmp_path / "kdir").mkdir()
    (tmp_path / "pdir.png").mkdir()
    plot = tmp_path / "a.png"
    for args in (["--kalibr", tmp_path / "kdir"], ["--kalibr", tmp_path / "kdir", "--force"]):
        status, _, err = run(logs["static"], "--out", plot, *args)
        assert status == 2, err
        assert "argument --kalibr" in one_error_line(err) and "kdir is a folder" in err
        assert not plot.exists()
    status, _, err = run(logs["static"], "--out", tmp_path / "pdir.png", "--force")
    assert status == 2 and "argument --out" in one_error_line(err) and "pdir.png is a folder" in err


def test_an_output_folder_that_cannot_take_a_file_is_refused_naming_the_option(logs, tmp_path, monkeypatch):
    """A read-only mount cannot be made here: ``folder_problem`` says it of the folder ``ro``."""
    ro = tmp_path / "ro"
    ro.mkdir()
    os.symlink(logs["static"], ro / "static.mcap")
    real = atomic.folder_problem
    monkeypatch.setattr(
        atomic, "folder_problem", lambda f: "read-only file system" if os.fspath(f) == os.fspath(ro) else real(f)
    )
    plot = tmp_path / "a.png"
    for args, argument in (
        ([ro / "static.mcap"], "--out (default"),
        ([logs["static"], "--out", ro / "x.png"], "--out:"),
        ([logs["static"], "--out", plot, "--kalibr", ro / "k.yaml"], "--kalibr:"),
    ):
        status, _, err = run(*args)
        assert status == 2, err
        line = one_error_line(err)
        assert f"argument {argument}" in line and "read-only file system" in line, line
        assert not plot.exists() and os.listdir(ro) == ["static.mcap"]


def test_a_broken_npz_log_is_a_clear_error_naming_it(logs, tmp_path):
    rng = np.random.default_rng(0)
    good = tmp_path / "good.npz"
    np.savez(good, **{"imu/gyro": rng.normal(size=(20_000, 3)), "imu/t": np.arange(20_000) * 1e-3})
    empty, truncated, text, mcap, pickled = (tmp_path / f"{n}.npz" for n in ("e", "h", "t", "m", "p"))
    empty.write_bytes(b"")
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    text.write_text("not a log\n")
    shutil.copyfile(logs["static"], mcap)
    np.savez(pickled, **{"imu/gyro": np.array([None] * 3, dtype=object), "imu/t": np.arange(3.0)})
    for path, words in (
        (empty, "empty file"),
        (truncated, "truncated or corrupt .npz"),
        (text, "not a gyroemu log"),
        (mcap, "MCAP log without the .mcap suffix"),
        (pickled, "object (pickled) arrays"),
    ):
        with pytest.raises(AllanLogError, match=re.escape(f"{path}: ")) as caught:
            allan_of_log(path)
        assert words in str(caught.value) and "allow_pickle" not in str(caught.value)
        status, _, err = run(path, "--out", tmp_path / "a.png")
        assert status == 2 and f"argument LOG: {path}: " in one_error_line(err) and words in err

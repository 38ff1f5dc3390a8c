"""``gyroemu allan`` results people can trust: the static check, terms reported with their interval or
as not resolved, the accelerometer beside the gyro, plots in the format named, Kalibr's imu.yaml and
the JSON report.

Logs are short (``consumer_mems`` at 1 kHz, 60 s static, 20 s of manoeuvre) to keep the suite fast.
"""

from __future__ import annotations

import json
import re
import warnings

import numpy as np
import pytest
from cli_runs import run_cli

from gyroemu.pipelines.formats.mcap_log import read_mcap
from gyroemu.pipelines.jobs.allan import (
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

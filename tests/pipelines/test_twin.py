"""``gyroemu twin``: a recording with truth beside its emulated twins.

The synthetic case: ``gyroemu simulate`` writes 30 s of ``smooth_manoeuvre`` sensed by ``tactical_mems``
(seed 0), and the twins sense the same (smooth, noise-free) motion with the same device, two seeds.
The twins are then draws of the very process that made the "real" log, so their RMSE and residual
Allan deviations differ from the real ones only by the seed-to-seed spread (about ±10 % on 30 s) and
the spline's re-fit of the truth (well below the sensor noise): ratios within [0.6, 1.6] for the
filter errors and [0.5, 2] for the Allan deviations (the long τ hold few clusters) are a loose bound
that a wrong truth alignment, unit or mask (factors of many) cannot meet.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from broad_trials import BROAD_DIR, needs_trial  # noqa: E402

from gyroemu.pipelines import cli  # noqa: E402
from gyroemu.pipelines.jobs.twin import METRICS, TwinError, TwinOptions, run_twin, twin_seed  # noqa: E402


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("twin") / "syn.mcap"
    code = cli.main(
        [
            "simulate",
            "--scenario",
            "smooth_manoeuvre",
            "--duration",
            "30",
            "--device",
            "tactical_mems",
            "--out",
            str(out),
        ]
    )
    assert code in (0, None)
    return out


@pytest.fixture(scope="module")
def report(synthetic, tmp_path_factory):
    out = tmp_path_factory.mktemp("twin_out") / "report"
    code = cli.main(
        [
            "twin",
            str(synthetic),
            "--device",
            "tactical_mems",
            "--seeds",
            "2",
            "--filter",
            "mekf",
            "--filter",
            "vqf",
            "--workers",
            "1",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    return out


def test_report_files_and_fields(report):
    assert (report / "twin.md").is_file() and (report / "syn.png").is_file()
    data = json.loads((report / "twin.json").read_text())
    assert data["settings"]["seeds"] == 2 and data["settings"]["filters"] == ["mekf", "vqf"]
    (trial,) = data["trials"]
    assert trial["mode"] == "6D"  # tactical_mems has no magnetometer
    for fr in trial["filters"]:
        assert set(fr["real"]) == set(METRICS) == set(fr["twin"]) == set(fr["ratio"])
        assert len(fr["twin"]["inclination_6d"]["values"]) == 2
        assert 0.6 <= fr["ratio"]["inclination_6d"] <= 1.6, fr
    for key in ("gyro", "accel"):
        r = trial["residuals"][key]
        assert len(r["ratio"]) == len(trial["residuals"]["tau_s"])
        assert 0.5 <= r["ratio_min"] <= r["ratio_max"] <= 2.0, (key, r["ratio_min"], r["ratio_max"])
        assert all(0.7 <= v <= 1.4 for v in r["psd_ratio"]), r["psd_ratio"]
    assert "ranking" in trial and "timings_s" in data
    md = (report / "twin.md").read_text()
    assert "6D inclination" in md and "Allan ratio" in md
    # Twin i's seed comes from i and the file name: reported, and distinct per recording.
    assert trial["source"]["twin_seeds"] == [twin_seed(i, "syn.mcap") for i in range(2)]


def test_twin_seeds_differ_between_recordings_and_repeat():
    """Twin i of two recordings draws from different seeds (pooling their rests pools independent
    draws), and the same recording's twin i from the same seed, run after run."""
    seeds = {name: [twin_seed(i, name) for i in range(5)] for name in ("02_a.hdf5", "07_b.hdf5", "log.mcap")}
    flat = [s for v in seeds.values() for s in v]
    assert len(set(flat)) == len(flat)
    assert seeds["02_a.hdf5"] == [twin_seed(i, "02_a.hdf5") for i in range(5)]
    assert all(isinstance(s, int) and 0 <= s < 2**64 for s in flat)


def test_existing_out_refused_without_force(synthetic, report, capsys):
    args = [
        "twin",
        str(synthetic),
        "--device",
        "tactical_mems",
        "--seeds",
        "1",
        "--filter",
        "vqf",
        "--out",
        str(report),
    ]
    with pytest.raises(SystemExit) as e:
        cli.main(args)
    assert e.value.code == 2 and "--out" in capsys.readouterr().err


@pytest.mark.parametrize(
    "extra, named",
    [
        (["--seeds", "0"], "--seeds"),
        (["--filter", "no_such_filter"], "--filter"),
        (["--device", "no_such_device"], "--device"),
        (["--site", "/nonexistent/site.toml"], "--site"),
        (["--workers", "0"], "--workers"),
        (["--smoothing", "position_cutoff_hz=600"], "--smoothing"),  # above the truth's Nyquist, 500 Hz
        (["--smoothing", "orientation_cutoff_hz=-1"], "--smoothing"),
        (["--smoothing", "no_such_key=1"], "--smoothing"),
    ],
)
def test_argument_errors_exit_2_before_work(synthetic, tmp_path, capsys, monkeypatch, extra, named):
    from gyroemu.pipelines.jobs import twin

    def no_work(*args, **kwargs):
        raise AssertionError("the real log's filters ran before the arguments were checked")

    monkeypatch.setattr(twin, "run_real", no_work)
    out = tmp_path / "o"
    with pytest.raises(SystemExit) as e:
        cli.main(["twin", str(synthetic), "--out", str(out), *extra])
    assert e.value.code == 2
    assert named in capsys.readouterr().err
    assert not out.exists()  # nothing written


@pytest.mark.parametrize(
    "table, named",
    [
        ("accel_offset_m_s2 = [0.01, 0.02]", "accel_offset_m_s2"),
        ("accel_offset_sigma_m_s2 = [0.01, -0.02, 0.0]", "accel_offset_sigma_m_s2"),
        ('accel_offset_m_s2 = [0.0, "a", 0.0]', "accel_offset_m_s2"),
        ("offset = [0.0, 0.0, 0.0]", "unknown keys"),
    ],
)
def test_bad_handling_table_exits_2_naming_the_key(synthetic, tmp_path, capsys, table, named):
    site = tmp_path / "site.toml"
    site.write_text(f"[site]\nmagnetic_field_enu_uT = [0.0, 14.25, -39.72]\n\n[handling]\n{table}\n")
    out = tmp_path / "o"
    with pytest.raises(SystemExit) as e:
        cli.main(["twin", str(synthetic), "--site", str(site), "--out", str(out)])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "--site" in err and "[handling]" in err and named in err, err
    assert not out.exists()


@pytest.mark.parametrize(
    "text, named",
    [
        ("[site]\n\n[bogus]\nx = 1\n", "key 'bogus': unknown table [bogus]"),
        ("[site]\nfoo_uT = 1.0\n", "key 'site.foo_uT': unknown key"),
        ("[site]\nlatitude_deg = nan\n", "key 'site.latitude_deg': expected a finite number, got nan"),
        ("[site]\nfoo_uT = 1.0\nlatitude_deg = nan\n", "key 'site.foo_uT': unknown key"),
    ],
)
def test_a_bad_site_file_is_one_line_naming_the_file_and_key(tmp_path, text, named):
    """A table the site file does not take is refused (not ignored); a bad [site] key is named on one
    line, not as pydantic's multi-line report with a URL."""
    from gyroemu.pipelines.twin import SiteFileError, read_site

    site = tmp_path / "site.toml"
    site.write_text(text)
    with pytest.raises(SiteFileError) as e:
        read_site(site)
    message = str(e.value)
    assert message.startswith(f"{site}: {named}") and "\n" not in message and "pydantic" not in message, message


def test_the_twins_filters_are_told_the_twins_rate(synthetic, tmp_path, monkeypatch):
    """The twins are sampled at the device's rate (here 285.7 Hz against the log's 1 kHz): their filters,
    which step at 1 / rate, are set up with it, and the real log's with its own (they were given the
    log's: VQF's twin error was 44° against 9°)."""
    from gyroemu.pipelines.jobs import twin
    from gyroemu.sensors import load_device

    rates = {}
    real_run, twin_run = twin.run_real, twin.run_one_twin

    def spy_real(real, filters, setup9, setup6, rests):
        rates["real"] = setup6.rate_hz
        return real_run(real, filters, setup9, setup6, rests)

    def spy_twin(real, site, smoothing, device_name, seed, filters, setup9, setup6, *rest):
        rates["twin"] = setup6.rate_hz
        return twin_run(real, site, smoothing, device_name, seed, filters, setup9, setup6, *rest)

    monkeypatch.setattr(twin, "run_real", spy_real)
    monkeypatch.setattr(twin, "run_one_twin", spy_twin)
    options = TwinOptions(
        trials=[synthetic], device="aktos_t_broad", seeds=1, filters=["vqf"], workers=1, out=tmp_path / "o"
    )
    run_twin(options)
    assert rates["real"] == pytest.approx(1000.0, rel=1e-12)  # the log's own, from its exact stamps
    assert rates["twin"] == float(load_device("aktos_t_broad", seed=0).spec.rate_hz)


@needs_trial("02_undisturbed_slow_rotation_B.hdf5")
def test_a_recording_that_moves_throughout_has_no_rest(tmp_path):
    """BROAD's trial 02 cut to its movement (45–145 s): the rest detector, relative to the quietest
    stretch, finds quiet motion; a phase inside the movement mask is not rest, so the twins hold no
    motion still and no samples stand in for rest: before the first movement sample there are none, and
    a BROAD trial has no truth rate to take the sensor's residual in motion (the whole recording stood in,
    its motion read as the sensor's error)."""
    import h5py

    src = BROAD_DIR / "02_undisturbed_slow_rotation_B.hdf5"
    cut = tmp_path / "moving_02.hdf5"
    with h5py.File(src, "r") as f, h5py.File(cut, "w") as g:
        fs = float(f.attrs["sampling_rate"])
        part = slice(int(45 * fs), int(145 * fs))
        for key in f:
            g[key] = f[key][part]
        for key, value in f.attrs.items():
            g.attrs[key] = value
        assert g["movement"][:].all()
    report = run_twin(TwinOptions(trials=[cut], seeds=1, filters=["mekf"], workers=1, out=tmp_path / "o"))
    rest = report.trials[0].rest
    assert rest["intervals_s"] == [] and rest["still_s"] == [], rest
    assert rest["source"].startswith("none")


def test_an_out_folder_that_cannot_take_the_report_is_refused_before_work(tmp_path, monkeypatch):
    """--out (made, or its parent when missing) that cannot take a file: a read-only mount refuses even
    root, which a test cannot make, so folder_problem is told; named before any run, not an OSError after."""
    from gyroemu.pipelines.jobs import twin
    from gyroemu.pipelines.jobs.twin import check_options

    trial = tmp_path / "a.mcap"
    trial.write_bytes(b"")  # read after the options are checked
    locked = tmp_path / "ro"
    locked.mkdir()
    monkeypatch.setattr(twin, "folder_problem", lambda f: "read-only file system" if f == locked else None)
    for out in (locked, locked / "tw"):
        with pytest.raises(TwinError, match=f"argument --out: {locked}: read-only file system"):
            check_options(TwinOptions(trials=[trial], device="tactical_mems", filters=["vqf"], out=out))
    assert list(locked.iterdir()) == []


def test_the_same_trial_twice_is_refused_naming_it(tmp_path):
    """A recording given twice (by any path to it) would be reported twice and its rests pooled twice."""
    from gyroemu.pipelines.jobs.twin import check_options

    trial = tmp_path / "a.mcap"
    trial.write_bytes(b"")
    (tmp_path / "link.mcap").symlink_to(trial)
    for again in (trial, tmp_path / "link.mcap"):
        with pytest.raises(TwinError, match=f"argument TRIAL: {again} is given twice"):
            check_options(TwinOptions(trials=[trial, again], filters=["vqf"], out=tmp_path / "o"))


def test_an_input_is_never_overwritten_even_with_force(tmp_path):
    """A file of the report (twin.md, twin.json, <trial>.png) that is an input: the device file, the
    site file or a recording, by any path to it (a symbolic link): refused naming --out before any work,
    even with --force; an out folder holding only other files is taken."""
    from gyroemu.pipelines.jobs.twin import check_options, default_site_file

    out = tmp_path / "out"
    out.mkdir()
    trial = tmp_path / "a.mcap"
    trial.write_bytes(b"")  # read after the options are checked
    device = (Path(__file__).resolve().parents[2] / "configs" / "devices" / "tactical_mems.toml").read_text()
    (out / "twin.md").write_text(device)
    (out / "twin.json").write_text(default_site_file().read_text())
    (out / "a.png").symlink_to(trial)
    given = {"trials": [trial], "filters": ["vqf"], "out": out, "force": True}
    refused = {
        "twin.md": TwinOptions(**given, device=str(out / "twin.md")),
        "twin.json": TwinOptions(**given, device="tactical_mems", site=out / "twin.json"),
        "a.png": TwinOptions(**given, device="tactical_mems"),
    }
    for name, options in refused.items():
        with pytest.raises(TwinError, match=f"argument --out: {out / name} is an input"):
            check_options(options)
    (out / "a.png").unlink()
    check_options(refused["a.png"])  # twin.md and twin.json are no input of it: --force overwrites them
    assert (out / "twin.md").read_text() == device and trial.exists()


def test_a_trial_that_cannot_be_read_is_named_once(tmp_path):
    """The reader's message names the file already: the error says 'TRIAL: m/x.mcap: ...', not the
    file twice, nor the recorded scenario's key 'path'."""
    folder = tmp_path / "m"
    folder.mkdir()
    garbage = folder / "x.mcap"
    garbage.write_text("not a log")
    with pytest.raises(TwinError) as e:
        run_twin(TwinOptions(trials=[garbage], filters=["vqf"], out=tmp_path / "o"))
    assert str(e.value) == f"argument TRIAL: {garbage}: not an MCAP file (it does not start with the MCAP magic bytes)"


def test_a_one_sample_log_is_named_not_the_smoothing(tmp_path):
    """One sample has no interval: the recording is at fault, not --smoothing's 'Nyquist frequency nan Hz'."""
    import h5py

    from gyroemu.pipelines.formats.importers import import_broad

    trial = tmp_path / "one.hdf5"
    with h5py.File(trial, "w") as f:
        for name, width in (("imu_gyr", 3), ("imu_acc", 3), ("imu_mag", 3), ("opt_quat", 4)):
            f[name] = np.ones((1, width)) / (2.0 if name == "opt_quat" else 1.0)
        f["movement"] = np.zeros(1, bool)
        f.attrs["sampling_rate"] = 100.0
    log = tmp_path / "one.mcap"
    import_broad(trial, log)
    with pytest.raises(TwinError, match=f"argument TRIAL: {log}: holds 1 sample"):
        run_twin(TwinOptions(trials=[log], filters=["vqf"], out=tmp_path / "o"))


def test_missing_trial_named(tmp_path):
    with pytest.raises(TwinError, match="TRIAL"):
        run_twin(TwinOptions(trials=[tmp_path / "nope.hdf5"], out=tmp_path / "o"))


@pytest.mark.slow
@needs_trial("07_undisturbed_fast_rotation_B.hdf5")
def test_broad_trial_end_to_end(tmp_path):
    rep = run_twin(
        TwinOptions(
            trials=[BROAD_DIR / "07_undisturbed_fast_rotation_B.hdf5"], seeds=2, filters=["mekf", "vqf"], out=tmp_path
        )
    )
    paths = rep.save(tmp_path / "out")
    data = json.loads(Path(paths["json"]).read_text())
    (trial,) = data["trials"]
    ranking = trial["ranking"]
    assert trial["mode"] == "9D" and sorted(ranking["real"]) == sorted(ranking["twin"]) == ["mekf", "vqf"]
    assert ranking["same"] == (ranking["real"] == ranking["twin"])
    for fr in trial["filters"]:
        for m in METRICS:
            assert fr["real"][m] is not None and math.isfinite(fr["real"][m]) and fr["real"][m] > 0
            assert fr["twin"][m]["n"] == 2 and fr["twin"][m]["mean"] > 0 and fr["ratio"][m] > 0
    for key in ("gyro", "accel"):
        assert trial["residuals"][key]["ratio_min"] > 0
    # The default site's [handling] draws one accelerometer offset per twin over the movement mask.
    (drawn,) = [n for n in trial["notes"] if n.startswith("handling offsets")]
    assert drawn.split(": ", 1)[1].count("(") == 2 and "none" not in drawn


UNDISTURBED = [
    "02_undisturbed_slow_rotation_B.hdf5",
    "07_undisturbed_fast_rotation_B.hdf5",
    "11_undisturbed_slow_translation_B.hdf5",
    "16_undisturbed_fast_translation_B.hdf5",
]


@pytest.mark.slow
@needs_trial()
def test_twin_meets_the_6d_9d_and_ranking_targets_on_the_undisturbed_trials(tmp_path):
    """Issue 15's targets that the twin meets, held against regressions (README, "The twin"): for each
    filter the mean over the four trials of the twin/real 9D total RMSE lies in 0.75–1.33 and no trial
    outside 0.5–2; mekf, vqf, madgwick and mahony rank alike on twin and real in at least three trials;
    every filter's 6D inclination ratio on every trial lies in 0.75–1.33, or the real recording lies
    inside the twins' 95 % prediction interval (mean ± t₀.₉₇₅(n−1)·s·√(1 + 1/n) over the n seeds: where
    the twins themselves scatter by more than the band, one real draw cannot be held to it; trial 11's
    MEKF, whose twins spread by ±0.15° about 0.40° from the handling offset they draw, real 0.56°)."""
    from scipy.stats import t as student

    for name in UNDISTURBED:
        if not (BROAD_DIR / name).is_file():
            pytest.skip(f"BROAD data: {name} not found in {BROAD_DIR}")
    rep = run_twin(TwinOptions(trials=[BROAD_DIR / n for n in UNDISTURBED], seeds=5, out=tmp_path))
    data = json.loads(rep.to_json())
    ratios: dict[str, list[float]] = {}
    six_d = []
    for trial in data["trials"]:
        for fr in trial["filters"]:
            ratios.setdefault(fr["filter"], []).append(fr["ratio"]["total_9d"])
            twins, real = fr["twin"]["inclination_6d"], fr["real"]["inclination_6d"]
            n = twins["n"]
            half = student.ppf(0.975, n - 1) * twins["std"] * math.sqrt(1 + 1 / n)
            in_band = 0.75 <= fr["ratio"]["inclination_6d"] <= 1.33
            six_d.append(
                (
                    trial["name"],
                    fr["filter"],
                    fr["ratio"]["inclination_6d"],
                    in_band or abs(real - twins["mean"]) <= half,
                )
            )
    for name, values in ratios.items():
        assert 0.75 <= sum(values) / len(values) <= 1.33, (name, values)
        assert all(0.5 <= v <= 2.0 for v in values), (name, values)
    # The issue counts identical orders (the count up to pairs the seeds cannot tell apart, paired
    # Student t at 5 %, is printed beside it).
    assert sum(trial["ranking"]["same"] for trial in data["trials"]) >= 3
    within = sum(trial["ranking"]["same_within_spread"] for trial in data["trials"])
    print(f"rankings alike within the seeds' spread: {within} of 4")
    assert all(ok for *_, ok in six_d), six_d
    # Residuals at rest, pooled over the trials: within a factor of 1.25 of the real Allan deviation,
    # the gyro's at every τ (0.01–10 s), the accelerometer's up to 6.3 s. At 10 s its y and z miss:
    # one draw of that point scatters by ±17 % and ±12 % (README, "The twin", residuals).
    pooled = data["residuals_pooled"]
    tau = np.array(pooled["tau_s"])
    gyro, accel = np.array(pooled["gyro"]["ratio"]), np.array(pooled["accel"]["ratio"])
    assert np.all((gyro >= 0.8) & (gyro <= 1.25)), gyro
    assert np.all((accel[tau < 10] >= 0.8) & (accel[tau < 10] <= 1.25)), accel


def test_twin_attitude_is_the_reference_refined_by_the_gyro_and_still_at_rest():
    """twin_attitude on an exact rate and reference gives the reference back (the fusion's round-off);
    a gyro that lags by the stated delay is aligned first; the rest stretches are held at one attitude."""
    from gyroemu.dynamics.rotation import quat_angle, quat_from_rotvec, quat_multiply
    from gyroemu.pipelines.jobs.twin import twin_attitude

    fs = 200.0
    t = np.arange(4001) / fs
    rate = np.array([0.3, -0.5, 1.2])
    q = quat_multiply(quat_from_rotvec([0.2, -0.1, 0.7]), quat_from_rotvec(t[:, None] * rate))
    gyro = np.tile(rate, (len(t), 1))
    eps = np.finfo(float).eps
    same = twin_attitude(t, q, gyro, [], 0.0, (1.0, 0.0, 0.0, 0.0))
    assert np.max(quat_angle(same, q)) < 20 * len(t) * eps
    # a gyro that senses the motion 5 samples late, told so: the same attitude (the rate is constant,
    # so only the ends' alignment, clamped by interpolation, could differ)
    late = twin_attitude(t, q, np.roll(gyro, 5, axis=0), [], 5 / fs, (1.0, 0.0, 0.0, 0.0))
    assert np.max(quat_angle(late, q)) < 20 * len(t) * eps
    held = twin_attitude(t, q, gyro, [(2.0, 3.0)], 0.0, (1.0, 0.0, 0.0, 0.0))
    inside = (t >= 2.0) & (t <= 3.0)
    assert np.ptp(held[inside], axis=0).max() == 0.0 and np.allclose(np.linalg.norm(held[inside], axis=1), 1.0)
    assert np.array_equal(held[~inside], same[~inside])


def test_the_twins_filters_are_set_up_in_the_twins_site_the_logs_in_its_own(tmp_path, monkeypatch):
    """A gyroemu log sensed at 33.9° S in a field 45° east of north (declination atan2(20, 20)): its own
    filters are told that site, from its metadata; its twins, sensed in --site (the BROAD lab: field
    (0.0132, 14.25, -39.72) µT, so declination atan2(0.0132, 14.25) = 0.053°; latitude 52.5°, the site's
    default) by --device, are told theirs (they were given the log's, 45° off their field). Both
    declinations are one arctan2 of the site's numbers: equal to a few ulps of π/4."""
    from gyroemu.pipelines.jobs import twin
    from gyroemu.sensors import load_device

    scenario = tmp_path / "sydney.toml"
    scenario.write_text(
        'kind = "random-manoeuvre"\nduration_s = 10.0\nrate_hz = 200.0\nseed = 0\n\n'
        "[site]\nlatitude_deg = -33.9\nmagnetic_field_enu_uT = [20.0, 20.0, -40.0]\n"
    )
    log = tmp_path / "sydney.mcap"
    assert cli.main(["simulate", "--scenario", str(scenario), "--device", "aktos_t_broad", "--out", str(log)]) in (
        0,
        None,
    )
    given = {}
    real_run, twin_run = twin.run_real, twin.run_one_twin

    def spy_real(real, filters, setup9, setup6, rests):
        given["real"] = (setup9, setup6)
        return real_run(real, filters, setup9, setup6, rests)

    def spy_twin(real, site, smoothing, device_name, seed, filters, setup9, setup6, *rest):
        given["twin"] = (setup9, setup6)
        return twin_run(real, site, smoothing, device_name, seed, filters, setup9, setup6, *rest)

    monkeypatch.setattr(twin, "run_real", spy_real)
    monkeypatch.setattr(twin, "run_one_twin", spy_twin)
    run_twin(TwinOptions(trials=[log], seeds=1, filters=["vqf"], workers=1, out=tmp_path / "o"))
    ulps = 4 * np.finfo(float).eps
    device = load_device("aktos_t_broad", seed=0)
    for side, declination, latitude_deg in (
        ("real", math.atan2(20.0, 20.0), -33.9),
        ("twin", math.atan2(0.0132, 14.25), 52.5),
    ):
        assert all(setup is not None for setup in given[side]), side  # 9D and 6D
        for setup in given[side]:
            assert setup.declination_rad == pytest.approx(declination, rel=ulps, abs=0), (side, setup)
            assert setup.latitude_rad == pytest.approx(math.radians(latitude_deg), rel=ulps, abs=0), (side, setup)
            assert (setup.gyro_latency_s, setup.mag_latency_s) == (device.latencies[0], device.latencies[2])
    assert given["twin"][1].rate_hz == float(device.spec.rate_hz)


def test_recordings_of_the_same_name_draw_different_twins(synthetic, tmp_path):
    """Two recordings named alike (a/syn.mcap, b/syn.mcap; here the same log twice, so that only the
    seeds can tell their twins apart): the first keeps the seeds its name gives, the second draws its
    own, and its twin senses other noise (they had the same device draw, and pooling their rests
    pooled one draw twice)."""
    import shutil

    copies = []
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        copies.append(Path(shutil.copy(synthetic, tmp_path / folder / "syn.mcap")))
    report = run_twin(
        TwinOptions(trials=copies, device="tactical_mems", seeds=2, filters=["vqf"], workers=1, out=tmp_path / "o")
    )
    first, second = (trial.source["twin_seeds"] for trial in report.trials)
    assert first == [twin_seed(i, "syn.mcap") for i in range(2)]
    assert not set(first) & set(second) and len(set(second)) == 2
    stds = [trial.residuals["gyro"]["twin_std"] for trial in report.trials]
    assert stds[0] != stds[1]  # other noise: a continuous draw, equal only by accident


def test_the_seeds_of_recordings_with_their_own_names_are_kept():
    """A recording whose file name is its own draws from README's ``SeedSequence([i, crc32(name)])``, as
    before same-named recordings were told apart (the README's BROAD figures were drawn from it)."""
    import zlib

    for name in ("02_undisturbed_slow_rotation_B.hdf5", "07_undisturbed_fast_rotation_B.hdf5"):
        documented = [
            int(np.random.SeedSequence([i, zlib.crc32(name.encode())]).generate_state(1, np.uint64)[0])
            for i in range(3)
        ]
        assert [twin_seed(i, name) for i in range(3)] == documented
        assert [twin_seed(i, name, 0) for i in range(3)] == documented


def _hand_made_broad(path: Path, *, gap: slice | None = None, mag_nan: bool = False, fs: float = 100.0, n: int = 2000):
    """A BROAD-like trial: 20 s at 100 Hz of a slow yaw, still for the first 5 s then moving (the
    movement mask), its reference lost over ``gap``, its magnetometer NaN throughout with ``mag_nan``."""
    import h5py

    t = np.arange(n) / fs
    yaw = np.where(t < 5.0, 0.0, 0.2 * (t - 5.0))
    q = np.stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)], axis=1)
    if gap is not None:
        q[gap] = np.nan
    rng = np.random.default_rng(3)
    gyro = np.zeros((n, 3)) + 1e-3 * rng.standard_normal((n, 3))
    gyro[t >= 5.0, 2] += 0.2
    accel = np.tile([0.0, 0.0, 9.81], (n, 1)) + 1e-2 * rng.standard_normal((n, 3))
    mag = np.full((n, 3), np.nan) if mag_nan else np.tile([0.0, 20.0, -40.0], (n, 1))
    with h5py.File(path, "w") as f:
        f["imu_gyr"], f["imu_acc"], f["imu_mag"], f["opt_quat"] = gyro, accel, mag, q
        f["movement"] = t >= 5.0
        f.attrs["sampling_rate"] = fs


def test_a_reference_gap_longer_than_max_gap_is_named_before_any_work(tmp_path, capsys, monkeypatch):
    """A reference lost for 0.5 s (50 samples at 100 Hz: the step across is 0.51 s) against max_gap_s =
    0.25 s: exit 2 naming the trial argument, the file once and the key, before the real run (it was
    found by the first twin, after it, naming the file twice); --smoothing max_gap_s=1 bridges it."""
    from gyroemu.pipelines.jobs import twin

    class NoWork(Exception):
        pass

    def no_work(*args, **kwargs):
        raise NoWork

    monkeypatch.setattr(twin, "run_real", no_work)
    trial = tmp_path / "gap.hdf5"
    _hand_made_broad(trial, gap=slice(1000, 1050))
    out = tmp_path / "o"
    with pytest.raises(SystemExit) as e:
        cli.main(["twin", str(trial), "--filter", "vqf", "--workers", "1", "--out", str(out)])
    err = capsys.readouterr().err
    assert e.value.code == 2 and f"argument TRIAL: {trial}: a gap of 0.51 s" in err and "smoothing.max_gap_s" in err, (
        err
    )
    assert err.count(trial.name) == 1 and not out.exists()
    with pytest.raises(NoWork):  # checked, and on to the runs
        run_twin(
            TwinOptions(
                trials=[trial], filters=["vqf"], workers=1, out=out, smoothing={**twin.TWIN_SMOOTHING, "max_gap_s": 1.0}
            )
        )


def test_a_user_filter_without_a_name_is_refused_naming_filter(synthetic, tmp_path, capsys, monkeypatch):
    """A class with ``process`` but no ``name``: exit 2 naming --filter and what is missing, before any run
    (it passed the check, then every run failed and the report said so in a note, exit 0)."""
    from gyroemu.pipelines.jobs import twin

    def no_work(*args, **kwargs):
        raise AssertionError("the real log's filters ran before the arguments were checked")

    monkeypatch.setattr(twin, "run_real", no_work)
    module = tmp_path / "nameless.py"
    module.write_text(
        "class Nameless:\n"
        "    def __init__(self, setup):\n"
        "        self.setup = setup\n\n"
        "    def process(self, t, gyro, accel, mag=None):\n"
        "        raise RuntimeError('never run')\n"
    )
    out = tmp_path / "o"
    with pytest.raises(SystemExit) as e:
        cli.main(["twin", str(synthetic), "--filter", f"{module}:Nameless", "--workers", "1", "--out", str(out)])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "argument --filter" in err and "has no 'name'" in err, err
    assert not out.exists()

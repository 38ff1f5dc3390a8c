"""The ``recorded`` scenario kind: a motion written by gyroemu read back as truth, against the original.

The bound of issue 14: a motion sampled at 120 Hz with position noise σ_p = 0.1 mm and attitude noise
σ_θ = 0.05° per axis. For the λ the fit chose, the smoother is linear in the samples, so its error is
the sum of two parts:

- the **smoothing bias**, the same spline's error on the samples without noise (deterministic);
- the **noise**, whose standard deviation per axis is the closed form
  :func:`~gyroemu.dynamics.smoothing_spline.derivative_noise_std`: for the rate σ_θ g₁(λ_q) (a turn δ
  moves the quaternion's components by δ/2, and ω is twice their derivative), for the specific force
  sqrt((σ_p g₂(λ_p))² + (g σ_θ g₀(λ_q))²) (the position's second derivative, and gravity seen through
  the attitude's error).

By Minkowski's inequality the RMS error is at most the bias's RMS plus the noise's; the noise's RMS
over the span exceeds its standard deviation by 5/sqrt(2 n_eff) with negligible probability, n_eff the
independent values (span × 2 f_c per axis). Without noise, the fit's error is the cubic spline's
interpolation error, bounded by Hall & Meyer (J. Approx. Theory 16, 1976): |e'| ≤ h³ |f⁽⁴⁾| / 24 and
|e''| ≤ 3 h² |f⁽⁴⁾| / 8, with |f⁽⁴⁾| measured on the truth by finite differences at 1 kHz.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gyroemu.dynamics import ConfigError, load_scenario
from gyroemu.dynamics.recorded import MotionSamples, RecordedMotion, SmoothingOptions
from gyroemu.dynamics.rotation import quat_from_rotvec, quat_multiply, quat_rotate
from gyroemu.dynamics.smoothing_spline import derivative_noise_std
from gyroemu.pipelines.formats.motion_files import read_csv, read_tum, write_csv, write_tum

RATE, SIGMA_P, SIGMA_THETA = 120.0, 1e-4, math.radians(0.05)
SPAN = 120.0
EDGE = 2.0  # s left out at each end: the natural end conditions' boundary layer


def rms(x):
    return np.sqrt(np.mean(x**2, axis=0))


def noisy_copy(truth, seed):
    rng = np.random.default_rng(seed)
    q = quat_multiply(truth.q_wb, quat_from_rotvec(SIGMA_THETA * rng.standard_normal((len(truth), 3))))
    p = truth.pos_w + SIGMA_P * rng.standard_normal(truth.pos_w.shape)
    return q, p


def write_scenario(folder: Path, motion: str, fmt: str, extra: str = "") -> Path:
    path = folder / "motion.toml"
    path.write_text(f'kind = "recorded"\npath = "{motion}"\nformat = "{fmt}"\n{extra}')
    return path


@pytest.mark.parametrize("name", ["smooth_manoeuvre", "car_drive"])
def test_noisy_recording_within_the_derived_bound(tmp_path, name):
    scenario = load_scenario(name)
    truth = scenario.simulate(duration=SPAN, rate_hz=RATE)
    q, p = noisy_copy(truth, seed=1)
    write_tum(tmp_path / "m.tum", truth.t, q, p)
    recorded = load_scenario(write_scenario(tmp_path, "m.tum", "tum"))
    got = recorded.simulate(rate_hz=1000.0)
    ref = scenario.simulate(duration=SPAN, rate_hz=1000.0)
    assert len(got) == len(ref) and np.array_equal(got.t, ref.t)
    motion = recorded.spec.motion()
    clean = RecordedMotion(
        MotionSamples(truth.t, truth.q_wb, truth.pos_w),
        SmoothingOptions(position_lambda=motion.position_lambda, orientation_lambda=motion.orientation_lambda),
    ).trajectory(got.t, got.environment)
    h = 1.0 / RATE
    g0, g1 = (derivative_noise_std(motion.orientation_lambda, h, k, SIGMA_THETA) for k in (0, 1))
    g2 = derivative_noise_std(motion.position_lambda, h, 2, SIGMA_P)
    inner = (got.t > EDGE) & (got.t < SPAN - EDGE)
    for field, sigma, fc in (
        ("omega_b", g1, motion.orientation_cutoff_hz),
        ("specific_force_b", math.hypot(g2, 9.81 * g0), min(motion.orientation_cutoff_hz, motion.position_cutoff_hz)),
    ):
        error = rms((getattr(got, field) - getattr(ref, field))[inner])
        bias = rms((getattr(clean, field) - getattr(ref, field))[inner])
        n_eff = (SPAN - 2 * EDGE) * 2 * fc
        bound = bias + sigma * (1 + 5 / math.sqrt(2 * n_eff))
        assert np.all(error <= bound), (field, error, bias, sigma)
        # The noise part is the closed form's, not smaller: the bound is not loose by construction.
        noise = rms((getattr(got, field) - getattr(clean, field))[inner])
        assert np.all(np.abs(noise / sigma - 1) <= 5 / math.sqrt(2 * n_eff)), (field, noise, sigma)


@pytest.mark.parametrize("name", ["smooth_manoeuvre", "car_drive"])
def test_clean_recording_within_the_interpolation_error(tmp_path, name):
    scenario = load_scenario(name)
    span = 60.0
    truth = scenario.simulate(duration=span, rate_hz=RATE)
    write_tum(tmp_path / "m.tum", truth.t, truth.q_wb, truth.pos_w)
    got = load_scenario(write_scenario(tmp_path, "m.tum", "tum")).simulate(rate_hz=1000.0)
    ref = scenario.simulate(duration=span, rate_hz=1000.0)
    env = ref.environment
    d = 1e-3
    q = ref.q_wb
    q4 = (q[4:] - 4 * q[3:-1] + 6 * q[2:-2] - 4 * q[1:-3] + q[:-4]) / d**4
    # p⁽⁴⁾ = d²a/dt², a_w = R_wb f_b − 2 Ω × v + g (the Trajectory's definition of f_b, inverted)
    acc = quat_rotate(ref.q_wb, ref.specific_force_b) - 2 * np.cross(env.earth_rate_w, ref.vel_w) + env.gravity_w
    p4 = (acc[2:] - 2 * acc[1:-1] + acc[:-2]) / d**2
    inner = (ref.t > EDGE) & (ref.t < span - EDGE)
    q4max, p4max = np.abs(q4[inner[2:-2]]).max(), np.abs(p4[inner[1:-1]]).max()
    h = 1.0 / RATE
    # |δω| ≤ 2 |δq̇| ≤ 2 · 2 · h³ max|q_i⁽⁴⁾| / 24 (four components); |δf| ≤ |δa| + g |δθ|, δθ ≤ 2 |δq|.
    bound_omega = 4 * h**3 / 24 * q4max
    bound_force = math.sqrt(3) * 3 / 8 * h**2 * p4max + 9.81 * 4 * 5 / 384 * h**4 * q4max
    assert np.linalg.norm(got.omega_b - ref.omega_b, axis=1)[inner].max() <= bound_omega
    assert np.linalg.norm(got.specific_force_b - ref.specific_force_b, axis=1)[inner].max() <= bound_force


def test_formats_agree_and_world_rotation_applies(tmp_path):
    truth = load_scenario("smooth_manoeuvre").simulate(duration=20.0, rate_hz=RATE)
    write_tum(tmp_path / "m.tum", truth.t, truth.q_wb, truth.pos_w)
    write_csv(tmp_path / "m.csv", truth.t, truth.q_wb, truth.pos_w)
    a, b = read_tum(tmp_path / "m.tum"), read_csv(tmp_path / "m.csv")
    assert np.array_equal(a.t, b.t) and np.array_equal(a.q_wb, b.q_wb) and np.array_equal(a.pos_w, b.pos_w)
    assert np.array_equal(a.t, truth.t) and np.array_equal(a.pos_w, truth.pos_w)  # full precision text
    # A world whose x points north: ENU is it turned +90° about z.
    q_ew = np.array([math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)])
    q_file = quat_multiply(q_ew * [1, -1, -1, -1], truth.q_wb)
    p_file = quat_rotate(q_ew * [1, -1, -1, -1], truth.pos_w)
    write_tum(tmp_path / "n.tum", truth.t, q_file, p_file)
    turned = load_scenario(
        write_scenario(tmp_path, "n.tum", "tum", f"world_to_enu_quat = {list(map(float, q_ew))}\n")
    ).simulate(rate_hz=RATE)
    plain = load_scenario(write_scenario(tmp_path, "m.csv", "csv")).simulate(rate_hz=RATE)
    for field in ("omega_b", "specific_force_b", "pos_w", "mag_b"):
        assert np.allclose(getattr(turned, field), getattr(plain, field), rtol=0, atol=1e-9), field


def test_simulate_writes_truth_pose_and_reads_back_as_recorded(tmp_path):
    from gyroemu.pipelines.formats.frames import SIMULATE_EPOCH_NS
    from gyroemu.pipelines.formats.mcap_log import read_mcap

    out = tmp_path / "run.mcap"
    run = [sys.executable, "-m", "gyroemu", "simulate", "--scenario", "smooth_manoeuvre", "--device", "ideal"]
    subprocess.run([*run, "--duration", "10", "--out", str(out)], check=True, capture_output=True)
    device = read_mcap(out).device
    ref = load_scenario("smooth_manoeuvre").simulate(duration=10.0, rate_hz=1000.0)
    assert device.pose is not None and np.array_equal(device.pose.t, device.truth.t)
    assert np.array_equal(device.pose.q_wb, device.truth.q_wb)
    assert np.array_equal(device.pose.t, device.samples.t)  # the pose at the IMU's stamps
    t = (device.stamp_ns - SIMULATE_EPOCH_NS) * 1e-9  # stamps count from simulate's fixed epoch
    k = np.rint(t * 1000).astype(int)  # the ideal device stamps its true instants k T
    on_grid = (np.abs(t - k / 1000) < 1e-9) & (k < len(ref))
    assert on_grid.sum() > 10
    assert np.allclose(device.pose.pos_w[on_grid], ref.pos_w[k[on_grid]], rtol=0, atol=1e-9)
    recorded = load_scenario(write_scenario(tmp_path, "run.mcap", "mcap"))
    motion = recorded.spec.motion()
    assert motion.has_position and motion.duration == pytest.approx(device.truth.t[-1] - device.truth.t[0])


@pytest.mark.parametrize(
    "device",
    [
        "ideal",
        "consumer_mems",
        "tactical_mems",
        "navigation_fog",
        "navigation_rlg",
        "classic_rate_gyro",
        "floated_rig",
        "free_gyro",
    ],
)
def test_every_preset_measures_a_recorded_motion(tmp_path, device):
    from gyroemu.pipelines.jobs.simulate import SimulateOptions, run_simulate
    from gyroemu.sensors import load_device

    truth = load_scenario("smooth_manoeuvre").simulate(duration=4.0, rate_hz=RATE)
    write_tum(tmp_path / "m.tum", truth.t, truth.q_wb, truth.pos_w)
    scenario = write_scenario(tmp_path, "m.tum", "tum")
    summary = run_simulate(SimulateOptions(scenario=str(scenario), out=tmp_path / "twin.npz", device=device))
    rate = load_device(device).spec.rate_hz
    data = np.load(tmp_path / "twin.npz")
    assert summary.duration_s == pytest.approx(4.0)
    assert np.median(np.diff(data["truth/t"])) == pytest.approx(1.0 / rate)  # truth at the device's rate
    assert summary.samples >= int(4.0 * rate) - 2


def test_broad_trial_as_recorded_motion():
    from broad_trials import BROAD_DIR, require_trial

    trial = "16_undisturbed_fast_translation_B.hdf5"
    require_trial(trial)
    scenario = load_scenario_dict({"kind": "recorded", "path": str(BROAD_DIR / trial), "format": "broad"})
    motion = scenario.spec.motion()
    assert motion.has_position and motion.gaps.invalid_rows > 0 and 0 < motion.gaps.longest_s < 0.25
    traj = scenario.simulate(rate_hz=285.714)
    assert np.all(np.isfinite(traj.omega_b)) and np.all(np.isfinite(traj.specific_force_b))
    # At rest before the movement |f| is the site's normal gravity plus the spline's acceleration noise
    # along it. The median of n samples errs by 1.2533 s/√n_eff (s their spread; the noise is correlated
    # over 1/(2 f_c), so n_eff = n h 2 f_c), plus the s²/(2g) that |·| adds: four of those.
    g = np.linalg.norm(traj.environment.gravity_w)
    norm = np.linalg.norm(traj.specific_force_b[:200], axis=1)
    spread = norm.std()
    n_eff = max(1.0, 200 / 285.714 * 2 * motion.position_cutoff_hz)
    assert abs(np.median(norm) - g) <= 4 * 1.2533 * spread / np.sqrt(n_eff) + spread**2 / (2 * g)


def load_scenario_dict(data):
    from gyroemu.dynamics.scenarios import scenario_from_dict

    return scenario_from_dict(data)


# ---------------------------------------------------------------------------------------------------
# Bad input: exit 2 naming the file and line or key, nothing written.


def gyroemu_simulate(scenario: Path, out: Path, *extra: str) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "gyroemu", "simulate", "--scenario", str(scenario), "--device", "ideal"]
    return subprocess.run([*command, "--out", str(out), *extra], capture_output=True, text=True)


def tum_lines(n=40, rate=RATE):
    t = np.arange(n) / rate
    return [f"{float(ti)!r} 0 0 0 0 0 0 1" for ti in t]


@pytest.mark.parametrize(
    "body, fmt, needle",
    [
        (None, "xyz", "format"),
        ("\n".join(tum_lines(5)), "tum", "valid samples"),
        ("\n".join(tum_lines()[:10] + [tum_lines()[10].replace(" 1", " 2")] + tum_lines()[11:]), "tum", "line 11"),
        ("\n".join(tum_lines()[:10] + [tum_lines()[10].replace(" 1", " 0")] + tum_lines()[11:]), "tum", "all zero"),
        ("\n".join(tum_lines()[:10] + [tum_lines()[8]] + tum_lines()[11:]), "tum", "line 11"),
        (
            "\n".join(tum_lines()[:10] + [tum_lines()[10].replace(" 0 0 0", " zero 0 0", 1)] + tum_lines()[11:]),
            "tum",
            "11",
        ),
        ("t_s, qw, qx, qy, qz, speed\n0, 1, 0, 0, 0, 3", "csv", "speed"),
        ("t_s, qw, qx, qy, qz\n0, 1, 0, 0, 0\n, 1, 0, 0, 0", "csv", "line 3: column 't_s' is empty"),
    ],
)
def test_bad_recordings_exit_2_before_any_work(tmp_path, body, fmt, needle):
    motion = tmp_path / "m.txt"
    motion.write_text(body if body is not None else "0 0 0 0 0 0 0 1\n")
    scenario = write_scenario(tmp_path, "m.txt", fmt)
    out = tmp_path / "twin.mcap"
    result = gyroemu_simulate(scenario, out)
    assert result.returncode == 2, result.stderr
    assert needle in result.stderr and ("m.txt" in result.stderr or "format" in result.stderr), result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.txt", "motion.toml"]


def test_long_gap_and_short_span_are_refused(tmp_path):
    t = np.r_[np.arange(100), 200 + np.arange(100)] / RATE  # 100 samples missing: 0.83 s
    q = np.tile([1.0, 0, 0, 0], (len(t), 1))
    write_tum(tmp_path / "m.tum", t, q, np.zeros((len(t), 3)))
    scenario = load_scenario(write_scenario(tmp_path, "m.tum", "tum"))
    with pytest.raises(ConfigError, match=r"gap of 0\.8.* s .*after t = 0\.825") as e:
        scenario.simulate()
    assert e.value.key == "smoothing.max_gap_s" and Path(e.value.file).name == "motion.toml"  # the key at fault
    allowed = load_scenario(write_scenario(tmp_path, "m.tum", "tum", "[smoothing]\nmax_gap_s = 1.0\n"))
    assert len(allowed.spec.motion().gaps.gaps) == 1
    # Longer than the recording, and shorter than two of the device's samples.
    result = gyroemu_simulate(tmp_path / "motion.toml", tmp_path / "a.mcap", "--duration", "100")
    assert result.returncode == 2 and "--duration" in result.stderr
    write_tum(tmp_path / "s.tum", np.arange(8) / 5000.0, q[:8], np.zeros((8, 3)))
    result = gyroemu_simulate(write_scenario(tmp_path, "s.tum", "tum"), tmp_path / "b.mcap")
    assert result.returncode == 2 and "shorter than two samples" in result.stderr, result.stderr
    assert not (tmp_path / "a.mcap").exists() and not (tmp_path / "b.mcap").exists()


def test_stated_cutoffs_set_the_smoothing(tmp_path):
    truth = load_scenario("smooth_manoeuvre").simulate(duration=10.0, rate_hz=RATE)
    write_tum(tmp_path / "m.tum", truth.t, truth.q_wb, truth.pos_w)
    extra = "[smoothing]\norientation_cutoff_hz = 5.0\nposition_cutoff_hz = 3.0\n"
    motion = load_scenario(write_scenario(tmp_path, "m.tum", "tum", extra)).spec.motion()
    assert motion.orientation_cutoff_hz == pytest.approx(5.0, rel=1e-6)
    assert motion.position_cutoff_hz == pytest.approx(3.0, rel=1e-6)
    bad = load_scenario(write_scenario(tmp_path, "m.tum", "tum", "[smoothing]\norientation_cutoff_hz = 80.0\n"))
    with pytest.raises(ConfigError, match="Nyquist") as e:
        bad.spec.motion()
    assert e.value.key == "smoothing.orientation_cutoff_hz" and Path(e.value.file).name == "motion.toml"
    with pytest.raises(ConfigError, match="world_to_enu_quat"):  # a zero quaternion is no rotation
        load_scenario(write_scenario(tmp_path, "m.tum", "tum", "world_to_enu_quat = [0.0, 0.0, 0.0, 0.0]\n"))


def test_a_gyroemu_logs_truth_is_read_at_its_exact_stamps(tmp_path):
    """A gyroemu log's stamps count from an epoch (``simulate``'s, 2026), where float64 seconds resolve
    0.24 µs: the truth at the samples' stamps is read at their exact nanoseconds, so the steps of a 1 kHz
    log are 1 ms to round-off (they were 1 ms ± 0.3 µs, which the smoothing read as jitter: a rate error
    of 10⁻⁴ rad/s on a noise-free log)."""
    from gyroemu.pipelines.formats.motion_files import read_motion

    out = tmp_path / "run.mcap"
    run = [sys.executable, "-m", "gyroemu", "simulate", "--scenario", "smooth_manoeuvre", "--device", "ideal"]
    subprocess.run([*run, "--duration", "2", "--out", str(out)], check=True, capture_output=True)
    t = read_motion(out, "mcap").t
    assert np.abs(np.diff(t) - 1e-3).max() <= 8 * np.finfo(float).eps * t[-1]


@pytest.mark.parametrize("fmt", ["tum", "csv"])
def test_epoch_stamps_in_a_text_file_are_read_at_their_digits(tmp_path, fmt):
    """TUM files stamp in epoch seconds (1.7·10⁹ s), where a double resolves 0.24 µs: parsed whole, exact
    10 ms steps read 9.99999–10.00023 ms, jitter the smoothing takes for motion (3.5 °/h of rate on a
    noise-free 100 Hz file). Read from their digits, the same motion stamped from 0 and from the epoch
    gives the same truth bit for bit, and the motion's clock keeps the epoch (``t0``). A byte-order mark,
    which spreadsheets write at a CSV's start, is no column name's."""
    truth = load_scenario("smooth_manoeuvre").simulate(duration=6.0, rate_hz=100.0)
    stamps = [f"{k // 100}.{k % 100 * 10_000:06d}" for k in range(len(truth))]  # exact decimal 10 ms steps
    epoch = [f"{1_700_000_000 + k // 100}.{k % 100 * 10_000:06d}" for k in range(len(truth))]
    runs = []
    for name, column, bom in (("zero", stamps, ""), ("epoch", epoch, "\ufeff")):
        values = np.column_stack([truth.q_wb, truth.pos_w])
        if fmt == "tum":
            rows = [f"{s} " + " ".join(repr(float(v)) for v in (*r[4:], *r[1:4], r[0])) for s, r in zip(column, values)]
        else:
            rows = ["t_s, qw, qx, qy, qz, px_m, py_m, pz_m"]
            rows += [f"{s}, " + ", ".join(repr(float(v)) for v in r) for s, r in zip(column, values)]
        (tmp_path / name).mkdir()
        (tmp_path / name / f"m.{fmt}").write_text(bom + "\n".join(rows) + "\n", encoding="utf-8")
        scenario = load_scenario(write_scenario(tmp_path / name, f"m.{fmt}", fmt))
        runs.append((scenario.spec.motion().t0, scenario.simulate(rate_hz=400.0)))
    (t0_zero, zero), (t0_epoch, at_epoch) = runs
    assert (t0_zero, t0_epoch) == (0.0, 1_700_000_000.0)
    for field in ("t", "q_wb", "omega_b", "specific_force_b", "pos_w"):
        assert np.array_equal(getattr(zero, field), getattr(at_epoch, field)), field


def test_a_stated_orientation_noise_is_the_attitudes_own(tmp_path):
    """``orientation_noise_deg`` is σ per axis: a turn of σ about each of three axes moves the unit
    quaternion by ½ σ along three directions at right angles to it, 3σ²/4 in all over its four
    components. Measured on turns drawn so (60,000 of them), the quaternion's total noise variance is
    3σ²/4 within its sampling error (5 standard errors of a variance from n draws: 5 √(2/n)), not the
    σ² that σ/2 per component makes; so the unbiased risk is given σ √3 / 4 per component (it was given
    σ/2, and smoothed the attitude too much: a cut-off 10 % low)."""
    from gyroemu.dynamics.smoothing_spline import choose_lambda

    rng = np.random.default_rng(11)
    n, sigma = 60_000, math.radians(0.05)
    q0 = quat_from_rotvec(rng.normal(size=(n, 3)))
    q = quat_multiply(q0, quat_from_rotvec(sigma * rng.standard_normal((n, 3))))
    q *= np.sign(np.einsum("ij,ij->i", q, q0))[:, None]
    total = np.mean(np.sum((q - q0) ** 2, axis=1))
    assert abs(total / (0.75 * sigma**2) - 1) <= 5 * math.sqrt(2 / n)
    assert abs(total / sigma**2 - 1) > 5 * math.sqrt(2 / n)  # σ/2 per component: far outside
    truth = load_scenario("smooth_manoeuvre").simulate(duration=20.0, rate_hz=RATE)
    noisy, _ = noisy_copy(truth, 3)
    motion = RecordedMotion(MotionSamples(t=truth.t, q_wb=noisy), SmoothingOptions(orientation_noise_rad=sigma))
    assert truth.t[0] == 0.0 and np.all(np.einsum("ij,ij->i", noisy[1:], noisy[:-1]) > 0)  # no time shift, no flip
    unit = noisy / np.linalg.norm(noisy, axis=1, keepdims=True)  # as the fit takes them
    assert motion.orientation_lambda == choose_lambda(truth.t, unit, sigma * math.sqrt(3.0) / 4.0)


def test_replaced_attitude_is_taken_at_the_recordings_own_stamps(tmp_path):
    """replace_attitude: an attitude given at other stamps (here 4× denser, a quarter turn about z from
    the recording's) is Slerped onto the recording's samples, a shared stamp giving its own row; with
    λ = 0 the spline interpolates them, so the fitted motion at the recording's stamps is the given
    attitude to round-off. Samples outside its span lose their attitude; after the fit, refused."""
    truth = load_scenario("smooth_manoeuvre").simulate(duration=10.0, rate_hz=RATE)
    write_tum(tmp_path / "m.tum", truth.t, truth.q_wb, truth.pos_w)
    exact = "[smoothing]\norientation_lambda_s3 = 0.0\n"
    scenario = load_scenario(write_scenario(tmp_path, "m.tum", "tum", exact))
    dense = load_scenario("smooth_manoeuvre").simulate(duration=10.0, rate_hz=4 * RATE)  # j/480 = k/120 at j = 4k
    turn = quat_from_rotvec([0.0, 0.0, math.pi / 2])
    given = quat_multiply(turn, dense.q_wb)
    given[-4 * 60 :] = np.nan  # the last half second has no given attitude
    scenario.spec.replace_attitude(dense.t, given)
    motion = scenario.spec.motion()
    kept = truth.t <= dense.t[-4 * 60 - 1]
    q_fit, _, _ = motion.attitude(truth.t[kept] - truth.t[0])
    dots = np.abs(np.einsum("ij,ij->i", q_fit, quat_multiply(turn, truth.q_wb[kept])))
    assert np.min(dots) > 1.0 - 1e3 * np.finfo(float).eps  # |q·q'| = cos(angle/2): angles below 1.3e-6 rad
    assert motion.duration == pytest.approx(truth.t[kept][-1] - truth.t[0], abs=1e-12)
    with pytest.raises(ValueError, match="fitted already"):
        scenario.spec.replace_attitude(dense.t, given)
    with pytest.raises(ValueError, match=r"\(M, 4\)"):
        load_scenario(write_scenario(tmp_path, "m.tum", "tum")).spec.replace_attitude(dense.t, given[:, :3])


def test_empty_cells_of_an_occluded_frame_are_a_gap(tmp_path):
    """A motion-capture export writes an occluded frame as empty cells (``1.25,,,,,,,``): they read as NaN,
    as ``nan`` cells do, so the rows are a gap, bridged up to ``smoothing.max_gap_s`` and refused beyond
    it naming the key and the time (they were refused as "'' is not a number", whatever their length).
    k frames lost between valid samples h apart make a gap of (k + 1) h. An empty stamp, and a cell that
    is no number, are errors naming the file, the line and the column."""
    from gyroemu.pipelines.formats.motion_files import MotionFileError

    truth = load_scenario("smooth_manoeuvre").simulate(duration=5.0, rate_hz=RATE)
    write_csv(tmp_path / "m.csv", truth.t, truth.q_wb, truth.pos_w)
    lines = (tmp_path / "m.csv").read_text().splitlines()  # the header, then row i on line i + 2

    def blank(rows: range, cell: str, name: str, stamp: bool = False) -> Path:
        out = list(lines)
        for i in rows:
            t = "" if stamp else out[i + 1].split(",")[0]
            out[i + 1] = ",".join([t] + [cell] * 7)
        (tmp_path / name).write_text("\n".join(out) + "\n")
        return tmp_path / name

    lost = range(240, 252)  # 12 frames: (12 + 1) / 120 Hz = 0.108 s
    empty, nan = read_csv(blank(lost, "", "e.csv")), read_csv(blank(lost, " nan", "n.csv"))
    assert np.array_equal(empty.q_wb, nan.q_wb, equal_nan=True)
    assert np.array_equal(empty.pos_w, nan.pos_w, equal_nan=True)
    assert np.array_equal(np.flatnonzero(~empty.valid()), np.array(lost))
    gaps = load_scenario(write_scenario(tmp_path, "e.csv", "csv")).spec.motion().gaps
    assert gaps.invalid_rows == len(lost) and len(gaps.gaps) == 1
    start, length = gaps.gaps[0]
    assert start == pytest.approx(truth.t[lost.start - 1], abs=1e-12) and length == pytest.approx(13 / RATE, rel=1e-9)

    long = blank(range(240, 300), "", "long.csv")  # 61 / 120 Hz = 0.51 s > max_gap_s = 0.25 s
    with pytest.raises(ConfigError, match=r"gap of 0\.508.* s .*after t = 1\.99") as e:
        load_scenario(write_scenario(tmp_path, long.name, "csv")).simulate()
    assert e.value.key == "smoothing.max_gap_s"

    with pytest.raises(MotionFileError, match=r"s\.csv: line 12: column 't_s' is empty"):
        read_csv(blank(range(10, 11), "", "s.csv", stamp=True))
    with pytest.raises(MotionFileError, match=r"x\.csv: line 12: column 'px_m': 'occluded' is not a number"):
        read_csv(blank(range(10, 11), "occluded", "x.csv"))

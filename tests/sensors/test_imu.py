"""The IMU around the mechanisms: sampling convention, mounting, lever arm, clock, seeds, noise budget."""

import re
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import CubicHermiteSpline

from gyroemu.dynamics import ConfigError, Environment, load_scenario, trajectory_from_world_motion
from gyroemu.dynamics.rotation import quat_from_rotvec, quat_rotate
from gyroemu.sensors import device_from_dict
from gyroemu.sensors.errors import MIN_LSB
from gyroemu.sensors.mechanism import GYRO_KINDS, GyroMechanism, GyroResponse, GyroTruth, mechanism_class

EPS = np.finfo(float).eps


def spinning(rate=(0.3, -0.2, 2.0), duration=4.0, hz=1000.0, env=None):
    """A body turning at a constant body rate ω (so q = exp(ω t / 2)), at rest at the origin."""
    t = np.arange(int(duration * hz) + 1) / hz
    w = np.broadcast_to(np.asarray(rate, float), (len(t), 3))
    q = quat_from_rotvec(t[:, None] * w)
    zero = np.zeros((len(t), 3))
    env = env or Environment.inertial(9.81, magnetic_field_w=(0.0, 2e-5, -4e-5))
    return trajectory_from_world_motion(t, q, w, zero, zero, zero, zero, env)


def wobbling(duration=3.0, hz=1000.0):
    """A body whose body rate varies: ω_b = (sin 3t, cos 2t, 0.5 + 0.2 sin 5t); attitude not needed."""
    t = np.arange(int(duration * hz) + 1) / hz
    w = np.stack([np.sin(3 * t), np.cos(2 * t), 0.5 + 0.2 * np.sin(5 * t)], -1)
    a = np.stack([3 * np.cos(3 * t), -2 * np.sin(2 * t), np.cos(5 * t)], -1)
    q = np.tile([1.0, 0, 0, 0], (len(t), 1))
    zero = np.zeros((len(t), 3))
    return trajectory_from_world_motion(t, q, w, a, zero, zero, zero, Environment.inertial(9.81))


def test_ideal_gyro_reports_the_exact_mean_rate_over_each_interval():
    traj = wobbling()
    antiderivative = CubicHermiteSpline(traj.t, traj.omega_b, traj.alpha_b).antiderivative()
    for rate in (1000.0, 250.0):
        s = device_from_dict({"description": "ideal", "rate_hz": rate}).measure(traj)
        assert len(s) == int(traj.duration * rate)
        np.testing.assert_allclose(s.t, np.arange(1, len(s) + 1) / rate, rtol=1e-12)
        expected = (antiderivative(s.t_true) - antiderivative(s.t_true - 1 / rate)) * rate
        # Exact for the Hermite interpolant: only round-off of the cumulative sums remains.
        np.testing.assert_allclose(s.gyro, expected, atol=len(traj) * EPS * 10)
        assert np.isnan(s.mag).all() and s.delta_angle is None


def test_mounting_rotation_and_increment_output():
    traj = spinning()
    q_bs = quat_from_rotvec([0.0, 0.0, np.pi / 2])  # sensor x along body y
    s = device_from_dict(
        {"description": "x", "rate_hz": 100, "output": "increment", "mounting": {"q_bs": q_bs.tolist()}}
    ).measure(traj)
    expected = quat_rotate(q_bs * [1, -1, -1, -1], traj.omega_b[0])
    np.testing.assert_allclose(s.gyro, np.broadcast_to(expected, s.gyro.shape), atol=1e-12)
    np.testing.assert_allclose(s.delta_angle, s.gyro / 100, rtol=1e-15)


def test_lever_arm_accelerometer_reads_centripetal_acceleration():
    # A body spinning at ω about z in free fall: a sensor at r reads f = ω × (ω × r) = −ω² r⊥.
    w = 5.0
    traj = spinning(rate=(0, 0, w), env=Environment.inertial(0.0))
    r = np.array([0.1, 0.0, 0.02])
    s = device_from_dict({"description": "x", "rate_hz": 200, "mounting": {"lever_arm_m": r.tolist()}}).measure(traj)
    np.testing.assert_allclose(s.accel, np.broadcast_to([-w * w * 0.1, 0, 0], s.accel.shape), atol=1e-9)


def test_clock_rate_error_scales_and_stamps_shift():
    traj = spinning()
    eps_ppm, offset = 200.0, 0.0125
    s = device_from_dict(
        {"description": "x", "rate_hz": 100, "clock": {"rate_error_ppm": eps_ppm, "offset_s": offset}}
    ).measure(traj)
    np.testing.assert_allclose(
        s.gyro, np.broadcast_to(traj.omega_b[0] * (1 + eps_ppm * 1e-6), s.gyro.shape), rtol=1e-12
    )
    np.testing.assert_allclose(s.t, np.arange(1, len(s) + 1) / 100 + offset, rtol=1e-13)
    np.testing.assert_allclose(s.t_true, np.arange(1, len(s) + 1) / 100 * (1 + eps_ppm * 1e-6), rtol=1e-13)


NOISY = {
    "description": "noisy",
    "rate_hz": 200,
    "gyro": {"errors": {"arw_deg_per_sqrt_h": 0.5, "bias_instability_deg_per_h": 5.0}},
    "accelerometer": {"errors": {"noise_density_ug_per_sqrt_hz": 100.0}},
}


def test_same_seed_same_bytes_and_streams_are_independent():
    traj = spinning(duration=10)
    a = device_from_dict(NOISY, seed=3).measure(traj)
    b = device_from_dict(NOISY, seed=3).measure(traj)
    c = device_from_dict(NOISY, seed=4).measure(traj)
    assert a.gyro.tobytes() == b.gyro.tobytes() and a.accel.tobytes() == b.accel.tobytes()
    noise_a, noise_c = a.gyro - traj.omega_b[0], c.gyro - traj.omega_b[0]
    r = np.corrcoef(noise_a[:, 0], noise_c[:, 0])[0, 1]
    assert abs(r) < 4 / np.sqrt(len(a))  # independent draws: |r| within 4σ of 0
    with_mag = device_from_dict({**NOISY, "magnetometer": {"noise_density_uT_per_sqrt_hz": 0.1}}, seed=3).measure(traj)
    assert with_mag.gyro.tobytes() == a.gyro.tobytes()  # a magnetometer draws from its own stream


def test_white_noise_through_the_device_matches_the_arw():
    traj = spinning(duration=60)
    spec = {"description": "x", "rate_hz": 200, "gyro": {"errors": {"arw_deg_per_sqrt_h": 0.5}}}
    s = device_from_dict(spec, seed=1).measure(traj)
    sigma = np.std(s.gyro - traj.omega_b[0], axis=0, ddof=1)
    expected = np.radians(0.5) / 60 * np.sqrt(200)  # N/√T
    # Sample standard deviation of n normal draws: relative standard error 1/√(2(n−1)); allow 5σ.
    assert np.all(np.abs(sigma / expected - 1) < 5 / np.sqrt(2 * (len(s) - 1)))


def test_magnetometer_hard_iron_and_soft_iron():
    traj = spinning(rate=(0, 0, 0))
    soft = [[1.1, 0.0, 0.0], [0.0, 0.9, 0.0], [0.0, 0.0, 1.0]]
    s = device_from_dict(
        {"description": "x", "rate_hz": 50, "magnetometer": {"hard_iron_uT": [5, -3, 1], "soft_iron": soft}}
    ).measure(traj)
    expected = np.array(soft) @ np.array([0.0, 2e-5, -4e-5]) + np.array([5e-6, -3e-6, 1e-6])
    np.testing.assert_allclose(s.mag, np.broadcast_to(expected, s.mag.shape), atol=1e-18)


class NoisyMechanism(GyroMechanism):
    kind: str = "ideal"

    def intrinsic_noise_density(self):
        return np.radians(1.0) / 60  # 1 deg/sqrt(h)

    def respond(self, truth, rng, state=None):
        return GyroResponse(rate=truth.omega)


def test_mechanism_noisier_than_its_spec_is_refused(monkeypatch):
    import gyroemu.sensors.imu

    monkeypatch.setattr(gyroemu.sensors.imu, "mechanism_class", lambda kind: NoisyMechanism)
    with pytest.raises(ConfigError, match="own white noise .* exceeds? the specified white noise") as info:
        device_from_dict(
            {"description": "x", "rate_hz": 100, "gyro": {"errors": {"arw_deg_per_sqrt_h": 0.5}}}, name="dev.toml"
        )
    assert info.value.key == "gyro.errors.arw_deg_per_sqrt_h" and info.value.file == "dev.toml"


@pytest.mark.parametrize(
    "edit, key",
    [
        ({"rate_hz": -5}, "rate_hz"),
        ({"gyro": {"mechanism": {"kind": "laser-sword"}}}, "gyro.mechanism.kind"),
        ({"gyro": {"errors": {"arw_deg_per_h": 0.1}}}, "gyro.errors.arw_deg_per_h"),
        ({"gyro": {"errors": {"arw_deg_per_sqrt_h": -0.1}}}, "gyro.errors.arw_deg_per_sqrt_h"),
        ({"gyro": {"errors": {"bandwidth_hz": 80}}}, "gyro.errors.bandwidth_hz"),
        ({"clock": {"jitter_s": 0.01}}, "clock.jitter_s"),
        ({"mounting": {"q_bs": [1, 1, 0, 0]}}, "mounting.q_bs"),
        # An open-loop FOG reads sin Δφ: beyond Δφ = π/2 (512 deg/s for the default coil) it folds back.
        (
            {"gyro": {"mechanism": {"kind": "fog", "loop": "open"}, "errors": {"range_deg_per_s": 600}}},
            "gyro.errors.range_deg_per_s",
        ),
        ({"gyro": {"mechanism": {"kind": "mems", "proof_mass_kg": -1e-9}}}, "gyro.mechanism.proof_mass_kg"),
    ],
)
def test_bad_device_config_names_the_key(edit, key):
    with pytest.raises(ConfigError) as info:
        device_from_dict({"description": "x", "rate_hz": 100, **edit}, name="dev.toml")
    assert info.value.key == key and info.value.file == "dev.toml"


@pytest.mark.parametrize(
    "kind, mechanism, key, limit",
    [
        ("mems", {"drive_frequency_hz": 1e12}, "drive_frequency_hz", "200000"),
        ("mems", {"model": "carrier", "drive_frequency_hz": 1e12}, "drive_frequency_hz", "200000"),
        ("rlg", {"simulation_rate_hz": 1e12}, "simulation_rate_hz", "1e+06"),
        ("rlg", {"dither_frequency_hz": 1e9}, "dither_frequency_hz", "10000"),
        ("rate-gyro", {"spring_stiffness_n_m_per_rad": 1e12}, "spring_stiffness_n_m_per_rad", "100000 Hz"),
        ("rate-gyro", {"gimbal_inertia_kgm2": 1e-15}, "spring_stiffness_n_m_per_rad", "100000 Hz"),
        ("rate-integrating", {"gimbal_inertia_kgm2": 1e-12}, "damping_n_m_s_per_rad", "100000 Hz"),
        (
            "rate-integrating",
            {"torque_rebalance": False, "gimbal_inertia_kgm2": 1e-12},
            "damping_n_m_s_per_rad",
            "100000 Hz",
        ),
        (
            "rate-integrating",
            # an integral corner of 0.16 Hz (above MIN_INTEGRAL_CORNER_HZ); the loop's pole √(k_t k_p/J) 225 kHz
            {"loop_proportional_a_per_rad": 1e9, "loop_integral_a_per_rad_s": 1e9},
            "loop_integral_a_per_rad_s",
            "100000 Hz",
        ),
    ],
)
def test_a_mechanism_whose_inner_rate_would_be_absurd_is_refused_naming_the_key(kind, mechanism, key, limit):
    """A key that sets how fast a mechanism is stepped inside (a MEMS drive of 10¹² Hz asked the carrier
    model for 2.4·10¹³ steps a simulated second) is bounded, the error naming it, its limit and why."""
    with pytest.raises(ConfigError, match=re.escape(f"more than the limit of {limit}")) as info:
        device_from_dict({"description": "x", "rate_hz": 100, "gyro": {"mechanism": {"kind": kind, **mechanism}}}, "d")
    assert info.value.key == f"gyro.mechanism.{key}", info.value
    assert "real" in info.value.reason  # the physical reason: what real gyros of the kind do


def test_an_output_too_slow_for_its_mechanism_is_refused_naming_rate_hz():
    """An output sample's inner grid must fit a block of the run (BLOCK_INNER_SAMPLES steps): a 32 kHz RLG
    read at 0.1 Hz would need 320 000 steps a sample in one block, refused naming rate_hz."""
    rlg = {"gyro": {"mechanism": {"kind": "rlg"}}}
    with pytest.raises(ConfigError, match="320000 steps of the gyro mechanism's inner grid") as info:
        device_from_dict({"description": "x", "rate_hz": 0.1, **rlg}, name="dev.toml")
    assert info.value.key == "rate_hz" and info.value.file == "dev.toml"
    assert device_from_dict({"description": "x", "rate_hz": 0.2, **rlg}).inner_rate_hz == 32_000.0


def test_the_inner_rate_limits_leave_every_shipped_device_and_the_mechanisms_defaults():
    """Every preset and every mechanism's defaults are well inside the bounds (their outputs unchanged)."""
    from gyroemu.sensors.presets import list_devices

    devices = list_devices()  # each shipped device file, validated
    assert len(devices) == len(list((Path(__file__).parents[2] / "configs" / "devices").glob("*.toml")))
    for device in devices:
        assert device.inner_rate_hz <= 1e5, device.name
    for kind in GYRO_KINDS:
        assert mechanism_class(kind)().inner_rate_hz(1000.0) <= 1e5, kind


@pytest.mark.parametrize(
    "sensor, key",
    [
        ("gyro", "noise_density_deg_per_s_per_sqrt_hz"),
        ("gyro", "arw_deg_per_sqrt_h"),
        ("accelerometer", "noise_density_ug_per_sqrt_hz"),
    ],
)
def test_a_white_noise_whose_per_sample_variance_overflows_is_refused_naming_the_key(sensor, key):
    """1e300 is a finite number, but its square per sample is not: refused when the device is read, not
    overflow warnings and NaN in the output."""
    with pytest.raises(ConfigError, match="per-sample variance beyond float64") as info:
        device_from_dict({"description": "x", "rate_hz": 1000, sensor: {"errors": {key: 1e300}}}, name="dev.toml")
    assert info.value.key == f"{sensor}.errors.{key}" and info.value.file == "dev.toml"
    device_from_dict({"description": "x", "rate_hz": 1000, sensor: {"errors": {key: 1e100}}}, name="dev.toml")


@pytest.mark.parametrize(
    "sensor, key, limit",
    [
        ("gyro", "quantisation_rad_per_s", 1000.0),
        ("accelerometer", "quantisation_m_per_s2", 1e7),
        # integrating outputs: a count of 1e300 was taken, every output sample 0
        ("gyro", "quantisation_rad", 0.1),
        ("accelerometer", "quantisation_m_per_s", 1.0),
    ],
)
def test_an_output_lsb_beyond_any_sensors_range_is_refused_naming_the_key(sensor, key, limit):
    """An output LSB of 1e300 made the quantiser's noise LSB² T / 12 overflow (OverflowError, a traceback);
    an LSB wider than the widest sensor's whole range is refused, the limit itself taken."""
    with pytest.raises(ConfigError, match=re.escape(f"more than the limit of {limit:g}: ")) as info:
        device_from_dict({"description": "x", "rate_hz": 1000, sensor: {"errors": {key: 1e300}}}, name="dev.toml")
    assert info.value.key == f"{sensor}.errors.{key}" and info.value.file == "dev.toml"
    device_from_dict({"description": "x", "rate_hz": 1000, sensor: {"errors": {key: limit}}}, name="dev.toml")


@pytest.mark.parametrize(
    "sensor, key",
    [
        ("gyro", "quantisation_rad_per_s"),
        ("accelerometer", "quantisation_m_per_s2"),
        ("gyro", "quantisation_rad"),
        ("accelerometer", "quantisation_m_per_s"),
    ],
)
def test_an_lsb_finer_than_any_real_output_is_refused_naming_the_key(sensor, key):
    """A subnormal LSB (1e-320) made the quantiser's count overflow and every output sample NaN, silently;
    an LSB finer than :data:`MIN_LSB` is refused, the limit itself taken and its output finite."""
    with pytest.raises(ConfigError, match=re.escape(f"less than the limit of {MIN_LSB:g}: ")) as info:
        device_from_dict({"description": "x", "rate_hz": 1000, sensor: {"errors": {key: 1e-320}}}, name="dev.toml")
    assert info.value.key == f"{sensor}.errors.{key}" and info.value.file == "dev.toml"
    noise = {"gyro": "noise_density_deg_per_s_per_sqrt_hz", "accelerometer": "noise_density_ug_per_sqrt_hz"}[sensor]
    errors = {key: MIN_LSB, noise: 1.0}
    device = device_from_dict({"description": "x", "rate_hz": 100, sensor: {"errors": errors}}, name="dev.toml")
    out = device.measure(load_scenario("bench_static").simulate(duration=1.0, rate_hz=100))
    assert np.all(np.isfinite(out.gyro)) and np.all(np.isfinite(out.accel))


@pytest.mark.parametrize("rate_hz, words", [(1e-300, "less than the limit of 0.1: "), (0.09, "less than the limit")])
def test_an_output_rate_slower_than_any_imu_is_refused_naming_rate_hz(rate_hz, words):
    """At 1e-300 Hz the error named the white-noise key (its per-sample variance N²/T underflowed) or the
    scenario (no sample in the run); 0.1 Hz, a tenth of the slowest IMU outputs, is the limit."""
    edit = {"gyro": {"errors": {"noise_density_deg_per_s_per_sqrt_hz": 0.0028, "quantisation_rad_per_s": 1e-3}}}
    with pytest.raises(ConfigError, match=re.escape(words)) as info:
        device_from_dict({"description": "x", "rate_hz": rate_hz, **edit}, name="dev.toml")
    assert info.value.key == "rate_hz" and "slowest IMU" in info.value.reason
    assert device_from_dict({"description": "x", "rate_hz": 0.1}).spec.rate_hz == 0.1


@pytest.mark.parametrize(
    "key, value, words",
    [
        ("initial_degC", 1e300, "more than the limit of 1000: "),  # a MEMS gyro's output NaN
        ("final_degC", 1e300, "more than the limit of 1000: "),
        ("initial_degC", -1e300, "absolute zero"),  # a traceback from the MEMS mechanism
        ("final_degC", -273.15, "absolute zero"),
    ],
)
def test_a_sensor_temperature_beyond_any_real_sensor_is_refused_naming_the_key(key, value, words):
    mems = {"gyro": {"mechanism": {"kind": "mems"}}}
    with pytest.raises(ConfigError, match=re.escape(words)) as info:
        device_from_dict({"description": "x", "rate_hz": 100, "temperature": {key: value}, **mems}, name="dev.toml")
    assert info.value.key == f"temperature.{key}" and info.value.file == "dev.toml"


def test_a_mems_gyro_at_the_hottest_temperature_reads_finite_numbers():
    temperature = {"initial_degC": 1000.0, "final_degC": 1000.0}
    mems = {"gyro": {"mechanism": {"kind": "mems"}}}
    device = device_from_dict({"description": "x", "rate_hz": 100, "temperature": temperature, **mems})
    samples = device.measure(spinning(duration=0.2, hz=100.0))
    assert np.isfinite(samples.gyro).all() and np.isfinite(samples.accel).all()


@pytest.mark.parametrize("sensor", ["gyro", "accelerometer"])
@pytest.mark.parametrize("bandwidth_hz", [1e-300, 0.099])
def test_an_output_low_pass_too_narrow_for_float64_is_refused_naming_it(sensor, bandwidth_hz):
    """1e-300 Hz stopped in a LinAlgError (singular matrices); below 10⁻⁴ of the output rate (0.1 Hz at 1 kHz)
    the second-order Butterworth's coefficients lose their digits. The limit itself is taken."""
    edit = {sensor: {"errors": {"bandwidth_hz": bandwidth_hz}}}
    with pytest.raises(ConfigError, match="less than the limit of 0.0001 of the output rate") as info:
        device_from_dict({"description": "x", "rate_hz": 1000, **edit}, name="dev.toml")
    assert info.value.key == f"{sensor}.errors.bandwidth_hz" and info.value.file == "dev.toml"
    device_from_dict({"description": "x", "rate_hz": 1000, sensor: {"errors": {"bandwidth_hz": 0.1}}})


def test_a_mechanism_whose_own_noise_leaves_float64_is_refused_not_an_overflow(monkeypatch):
    """The backstop behind the mechanisms' bounds: a noise of 1e300 (whose square overflowed in the budget,
    an OverflowError) is refused naming the mechanism's table."""
    from gyroemu.sensors.mechanism import IdealGyro

    monkeypatch.setattr(IdealGyro, "intrinsic_noise_density", lambda self: 1e300)
    with pytest.raises(ConfigError, match="own white noise would be 1e\\+300") as info:
        device_from_dict({"description": "x", "rate_hz": 1000}, name="dev.toml")
    assert info.value.key == "gyro.mechanism"


@pytest.mark.parametrize("kind", sorted(GYRO_KINDS))
def test_each_mechanism_reads_only_what_it_declares(kind):
    # The IMU leaves the optional truth fields a mechanism does not declare as None; run each
    # mechanism on such a truth (a slow turn about all axes) and check it answers on the inner grid.
    mechanism = mechanism_class(kind)()
    hz = mechanism.inner_rate_hz(200.0)
    t = np.arange(int(hz * 0.2) + 1) / hz
    omega = np.tile([0.01, -0.02, 0.03], (len(t), 1))
    optional = {
        "specific_force": np.tile([0.0, 0.0, 9.81], (len(t), 1)),
        "q_is": quat_from_rotvec(t[:, None] * omega),
        "temperature_degC": np.full(len(t), 25.0),
    }
    truth = GyroTruth(
        t=t,
        dt=1 / hz,
        omega=omega,
        alpha=np.zeros_like(omega),
        **{k: v for k, v in optional.items() if k in mechanism.reads},
    )
    response = mechanism.respond(truth, np.random.default_rng(0), {})
    out = response.angle if response.angle is not None else response.rate
    assert out.shape == (len(t), 3) and np.all(np.isfinite(out))


def test_output_quantiser_counts_in_the_noise_budget():
    # 1 deg/s LSB at 100 Hz: LSB²T/12 = (0.01745)²·0.01/12 → 5.04e-4 rad/√s of white noise, more than
    # a specified 0.5 deg/sqrt(h) (1.45e-4 rad/√s): refused. At 0.01 deg/s LSB it fits, and the total
    # white noise the device shows is the specified one.
    spec = {"description": "x", "rate_hz": 100, "gyro": {"errors": {"arw_deg_per_sqrt_h": 0.5}}}
    coarse = {**spec, "gyro": {"errors": {"arw_deg_per_sqrt_h": 0.5, "quantisation_rad_per_s": np.radians(1.0)}}}
    with pytest.raises(ConfigError, match="output quantiser") as info:
        device_from_dict(coarse, name="dev.toml")
    assert info.value.key == "gyro.errors.arw_deg_per_sqrt_h"
    fine = {**spec, "gyro": {"errors": {"arw_deg_per_sqrt_h": 0.5, "quantisation_rad_per_s": np.radians(0.01)}}}
    device = device_from_dict(fine)
    lsb_density2 = np.radians(0.01) ** 2 * 0.01 / 12
    np.testing.assert_allclose(device.gyro_errors.noise_density**2 + lsb_density2, (np.radians(0.5) / 60) ** 2)
    np.testing.assert_allclose(device.gyro_noise_density, np.radians(0.5) / 60)


def test_gyro_truth_compares_and_hashes_by_identity():
    """GyroTruth holds arrays: it compares by identity (no ambiguous element-wise ==) and can key a dict."""
    t = np.arange(4) * 0.01
    a = GyroTruth(t=t, dt=0.01, omega=np.zeros((4, 3)), alpha=np.zeros((4, 3)))
    b = GyroTruth(t=t, dt=0.01, omega=np.zeros((4, 3)), alpha=np.zeros((4, 3)))
    assert a == a and a != b
    assert {a: 1, b: 2}[a] == 1


# --- latency: each sensor reads its truth latency_s earlier than the device's instants ---------------

AMP, OMEGA = 0.3, 2 * np.pi * 2.0  # roll oscillation θ(t) = A sin Ωt about body (and world) x, rad, rad/s
SWAY, OMEGA_X = 0.01, 2 * np.pi * 3.0  # sway along world x, p(t) = a sin Ω_x t, m, rad/s
FIELD_W = np.array([3e-6, 2e-5, -4e-5])  # tesla
GRAVITY = 9.81


def oscillating(duration=3.0, hz=1000.0):
    """Roll θ(t) = A sin Ωt and sway p(t) = a sin Ω_x t along x, closed form at every instant:

    ω_b = θ' x,   f_b = R_bw (a_w − g_w) = (p'', g sin θ, g cos θ),
    m_b = R_bw m_w = (m_x, m_y cos θ + m_z sin θ, −m_y sin θ + m_z cos θ).
    """
    t = np.arange(int(round(duration * hz)) + 1) / hz
    theta = AMP * np.sin(OMEGA * t)
    x = np.array([1.0, 0.0, 0.0])
    q = quat_from_rotvec(theta[:, None] * x)
    w = (AMP * OMEGA * np.cos(OMEGA * t))[:, None] * x
    a = (-AMP * OMEGA**2 * np.sin(OMEGA * t))[:, None] * x
    pos = (SWAY * np.sin(OMEGA_X * t))[:, None] * x
    vel = (SWAY * OMEGA_X * np.cos(OMEGA_X * t))[:, None] * x
    acc = (-SWAY * OMEGA_X**2 * np.sin(OMEGA_X * t))[:, None] * x
    env = Environment.inertial(GRAVITY, magnetic_field_w=FIELD_W)
    return trajectory_from_world_motion(t, q, w, a, pos, vel, acc, env)


def _gauss_mean(f, start, end, points=12):
    """Mean of ``f`` over each interval ``[start, end]`` by Gauss–Legendre (exact to round-off here)."""
    x, wts = np.polynomial.legendre.leggauss(points)
    mid, half = (start + end) / 2, (end - start) / 2
    values = f(mid[:, None] + half[:, None] * x[None, :])  # (K, points, 3)
    return np.einsum("kpj,p->kj", values, wts) / 2


def _force_b(t):
    theta = AMP * np.sin(OMEGA * t)
    return np.stack([-SWAY * OMEGA_X**2 * np.sin(OMEGA_X * t), GRAVITY * np.sin(theta), GRAVITY * np.cos(theta)], -1)


def _field_b(t):
    theta = AMP * np.sin(OMEGA * t)
    c, s = np.cos(theta), np.sin(theta)
    m = FIELD_W
    return np.stack([np.full_like(t, m[0]), m[1] * c + m[2] * s, -m[1] * s + m[2] * c], -1)


def _fourth_derivative_bound(f, t):
    """max |f⁽⁴⁾| over ``t`` by a fourth central difference on a fine grid (a bound up to O(δ²))."""
    d = 1e-3 / 16
    return np.max(np.abs(f(t + 2 * d) - 4 * f(t + d) + 6 * f(t) - 4 * f(t - d) + f(t - 2 * d))) / d**4


LATENCY = {"gyro": 0.0043, "accelerometer": -0.0021, "magnetometer": 0.0127}


def test_latency_each_sensor_reads_the_truth_latency_earlier():
    hz, rate = 1000.0, 200.0
    traj = oscillating(hz=hz)
    spec = {
        "description": "lagging",
        "rate_hz": rate,
        "gyro": {"latency_s": LATENCY["gyro"]},
        "accelerometer": {"latency_s": LATENCY["accelerometer"]},
        "magnetometer": {"latency_s": LATENCY["magnetometer"]},
    }
    s = device_from_dict(spec).measure(traj)
    period = 1 / rate
    # First sample K₁ = 1 + ceil(L_max / T) = 1 + ceil(12.7 / 5) = 4; last K₂ = floor((3 − 0.0021) / T) = 599.
    k = np.arange(4, 600)
    assert len(s) == len(k)
    np.testing.assert_allclose(s.t, k * period, rtol=1e-13)
    np.testing.assert_allclose(s.t_true, k * period, rtol=1e-13)  # taken at τ_k: only the truth is shifted
    h = 1 / hz
    grid = np.linspace(0.01, 2.99, 30001)

    # Gyro: the mean rate over [τ_{k−1} − L, τ_k − L] is (θ(τ_k − L) − θ(τ_{k−1} − L)) / T, closed form.
    # The device integrates the cubic Hermite interpolant of (ω, α) at the truth's samples, whose error
    # is at most h⁴/384 max|ω⁽⁴⁾| = h⁴ A Ω⁵ / 384 (twice: re-sampled on the inner grid); round-off of
    # the cumulative sums adds ~ n_inner eps |θ|.
    lag = LATENCY["gyro"]
    end, start = s.t_true - lag, s.t_true - period - lag
    theta = lambda t: AMP * np.sin(OMEGA * t)  # noqa: E731
    expected = (theta(end) - theta(start)) / period
    bound = 2 * h**4 * AMP * OMEGA**5 / 384 + 10 * len(traj) * EPS * AMP / period
    assert np.max(np.abs(s.gyro[:, 0] - expected)) < bound
    np.testing.assert_array_equal(s.gyro[:, 1:], 0.0)
    unshifted = (theta(end + lag) - theta(start + lag)) / period
    assert np.max(np.abs(s.gyro[:, 0] - unshifted)) > 1e4 * bound  # the latency is what is seen

    # Accelerometer: mean of f_b over the shifted interval (x closed form, y and z by Gauss–Legendre);
    # the truth's cubic spline errs by at most 5h⁴/384 max|f⁽⁴⁾|, Simpson's rule far less.
    lag = LATENCY["accelerometer"]
    end, start = s.t_true - lag, s.t_true - period - lag
    expected = _gauss_mean(_force_b, start, end)
    expected[:, 0] = SWAY * OMEGA_X * (np.cos(OMEGA_X * end) - np.cos(OMEGA_X * start)) / period
    bound = 2 * 5 * h**4 / 384 * _fourth_derivative_bound(_force_b, grid) + 100 * EPS * GRAVITY
    assert np.max(np.abs(s.accel - expected)) < bound

    # Magnetometer: the field at τ_k − L, cubic spline of the truth's samples.
    lag = LATENCY["magnetometer"]
    expected = _field_b(s.t_true - lag)
    bound = 2 * 5 * h**4 / 384 * _fourth_derivative_bound(_field_b, grid) + 100 * EPS * np.linalg.norm(FIELD_W)
    assert np.max(np.abs(s.mag - expected)) < bound


def test_latency_zero_is_the_device_without_it_and_round_trips_through_toml(tmp_path):
    from gyroemu.sensors import load_device

    traj = oscillating(duration=2.0)
    base = {**NOISY, "magnetometer": {"noise_density_uT_per_sqrt_hz": 0.1}}
    plain = device_from_dict(base, seed=5)
    zero = device_from_dict(
        {
            **base,
            "gyro": {**base["gyro"], "latency_s": 0.0},
            "accelerometer": {**base["accelerometer"], "latency_s": 0},
            "magnetometer": {**base["magnetometer"], "latency_s": 0.0},
        },
        seed=5,
    )
    assert zero.to_toml() == plain.to_toml() and "latency_s" not in plain.to_toml()
    a, b = plain.measure(traj), zero.measure(traj)
    for name in ("t", "gyro", "accel", "mag"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes()

    lagging = device_from_dict(
        {
            **base,
            "gyro": {**base["gyro"], "latency_s": 0.004},
            "accelerometer": {**base["accelerometer"], "latency_s": 0.002},
            "magnetometer": {**base["magnetometer"], "latency_s": 0.016},
        },
        seed=5,
    )
    path = tmp_path / "lagging.toml"
    path.write_text(lagging.to_toml())
    again = load_device(path, seed=5)
    assert again.latencies == (0.004, 0.002, 0.016) == lagging.latencies
    assert again.to_toml() == lagging.to_toml()
    c, d = lagging.measure(traj), again.measure(traj)
    assert len(c) == len(a) - 4  # K₁ = 1 + ceil(16 ms / 5 ms) = 5: four samples fewer at the start
    for name in ("t", "gyro", "accel", "mag"):
        assert getattr(c, name).tobytes() == getattr(d, name).tobytes()


@pytest.mark.parametrize("table", ["gyro", "accelerometer", "magnetometer"])
def test_latency_of_a_second_or_more_is_refused(table):
    with pytest.raises(ConfigError) as err:
        device_from_dict({"description": "x", "rate_hz": 100, table: {"latency_s": 1.0}})
    assert f"{table}.latency_s" in str(err.value)


class _Forces:
    """A stand-in truth whose specific force at the instants asked for is drawn at random."""

    def __init__(self, seed: int):
        self.rng = np.random.default_rng(seed)

    def specific_force(self, t):
        return 10.0 ** self.rng.uniform(-3, 2) * self.rng.standard_normal((len(t), 3))


@pytest.mark.parametrize("substeps", [2, 4, 6, 10, 20, 40])
def test_mean_specific_force_is_scipys_composite_simpson_bit_for_bit(substeps):
    """mean_specific_force sums scipy's Simpson panels without gathering each interval's points: the
    same bits as ``simpson(f[idx], dx=1/substeps, axis=1)`` (any difference is a wrong line)."""
    from scipy.integrate import simpson

    from gyroemu.sensors.accelerometer import mean_specific_force

    instants = 2.5 + np.arange(301) * 0.01
    ours = mean_specific_force(_Forces(substeps), instants, substeps)
    k = len(instants) - 1
    f = _Forces(substeps).specific_force(np.empty(k * substeps + 1))  # the same draws
    idx = np.arange(k)[:, None] * substeps + np.arange(substeps + 1)[None, :]
    assert ours.tobytes() == simpson(f[idx], dx=1.0 / substeps, axis=1).tobytes()


def test_mean_specific_force_refuses_an_odd_count_of_sub_intervals():
    from gyroemu.sensors.accelerometer import mean_specific_force

    with pytest.raises(ValueError, match="even number"):
        mean_specific_force(_Forces(0), np.arange(5.0), 3)

"""Ship in beam seas with and without a gyrostabiliser, checked against the linearised coupled
roll–pitch–gimbal system; spacecraft slewed by CMGs; config errors; the built-in files.

The ship checks compare with linear theory in a small sea, where the terms the linearisation drops are
bounded by ``φ²/6`` (``sin φ``) and ``δ²/2`` (``cos δ``) relative to those it keeps; the Earth's rotation
is switched off there so that only these terms separate simulation and theory.
"""

import numpy as np
import pytest

from gyroemu.dynamics import ConfigError, load_scenario, scenario_from_dict
from gyroemu.dynamics.rotation import quat_rotate
from gyroemu.dynamics.vessels import jonswap

EPS = np.finfo(float).eps

SMALL_SEA = {"significant_height_m": 0.1}
RECORD_S, RATE_HZ = 600.0, 5.0


def ship(stabiliser, waves=SMALL_SEA, earth=False, seed=3):
    data = {
        "kind": "ship",
        "duration_s": RECORD_S,
        "rate_hz": RATE_HZ,
        "seed": seed,
        "waves": dict(waves),
        "site": {"earth_rotation": earth},
    }
    if stabiliser is not None:
        data["stabiliser"] = stabiliser
    return scenario_from_dict(data).spec.model()


def record_bound(amplitudes, omega, n, dt):
    """Bound on |mean of x² over n samples − Σ c²/2| for x = Σ c_k cos(ω_k t + ψ_k) sampled every dt:
    each cross term averages a cosine, |(1/n) Σ cos(a t_i + b)| ≤ min(1, 1/(n |sin(a dt/2)|))."""

    def average(a):
        return np.minimum(1.0, 1.0 / (n * np.maximum(np.abs(np.sin(a * dt / 2)), 1e-300)))

    c, w = amplitudes, omega
    bound = np.sum(c**2 / 2 * average(2 * w))
    cc, wj, wk = np.outer(c, c), w[:, None], w[None, :]
    off = ~np.eye(c.size, dtype=bool)
    return bound + 0.5 * np.sum((np.abs(cc) * (average(wj - wk) + average(wj + wk)))[off])


def test_jonswap_integrates_to_hs_squared_over_16():
    w = np.linspace(0.05, 30.0, 400_000)
    for gamma in (1.0, 3.3):
        m0 = np.sum(jonswap(w, 2.0, 8.0, gamma)) * (w[1] - w[0])
        assert m0 == pytest.approx(2.0**2 / 16, rel=0.01)  # A_γ normalises to within about 1% (DNV)


def test_stabiliser_reduces_roll_as_the_linearised_roll_gimbal_system_predicts():
    bare, stab = ship(None), ship({})
    t = np.arange(int(RECORD_S * RATE_HZ) + 1) / RATE_HZ
    ms, ms_linear, ms_spectral, bounds = {}, {}, {}, {}
    for name, model in (("bare", bare), ("stabilised", stab)):
        traj = model.trajectory(t)
        roll = traj.extras["roll_rad"]
        linear = model.linear_response(t)  # Im Σ (iω_k − A)⁻¹ B M_k e^{i(ω_k t + θ_k)}
        ms[name], ms_linear[name] = np.mean(roll**2), np.mean(linear[:, 0] ** 2)
        # Same wave components: simulation and linear theory differ only by the dropped terms.
        delta_max = np.abs(traj.extras["gimbal_angle_rad"]).max() if name == "stabilised" else 0.0
        phi_max = np.abs(roll).max()
        nonlinear = 2 * (phi_max**2 / 6 + delta_max**2 / 2) + 1e-4  # mean squares: twice the amplitudes'
        assert abs(ms[name] / ms_linear[name] - 1) <= nonlinear, (name, ms[name] / ms_linear[name] - 1, nonlinear)
        # Spectral expectation Σ ½ |H(iω_k)|² M_k², and how far one record of this length may stray from it.
        w = model.waves
        c = np.abs(model.roll_transfer(w.omega)) * model.roll_moment_per_slope * w.wavenumber * w.amplitude
        ms_spectral[name] = np.sum(c**2) / 2
        assert model.roll_rms_theory() ** 2 == pytest.approx(ms_spectral[name], rel=1e-12)
        bounds[name] = record_bound(c, w.omega, t.size, 1 / RATE_HZ)
        assert abs(ms_linear[name] - ms_spectral[name]) <= bounds[name]
    ratio = np.sqrt(ms["stabilised"] / ms["bare"])
    ratio_linear = np.sqrt(ms_linear["stabilised"] / ms_linear["bare"])
    ratio_spectral = np.sqrt(ms_spectral["stabilised"] / ms_spectral["bare"])
    assert ratio < 0.6  # the default stabiliser takes at least 40% off the roll
    assert ratio == pytest.approx(ratio_linear, rel=2e-3)
    low = np.sqrt((ms_spectral["stabilised"] - bounds["stabilised"]) / (ms_spectral["bare"] + bounds["bare"]))
    high = np.sqrt((ms_spectral["stabilised"] + bounds["stabilised"]) / (ms_spectral["bare"] - bounds["bare"]))
    assert low <= ratio <= high, (low, ratio, ratio_spectral, high)


def test_gimbal_stays_within_its_stops_in_a_heavy_sea():
    model = ship({"gimbal_limit_deg": 45.0, "precession_gain": 12.0}, waves={"significant_height_m": 3.0}, earth=True)
    t = np.arange(0, 301) / 5.0
    traj = model.trajectory(t)
    delta = traj.extras["gimbal_angle_rad"]
    assert np.abs(delta).max() > np.radians(35.0)  # it does reach the fade zone
    # The fade makes the approach to a stop exponential; the integrator may overshoot by its tolerance.
    assert np.abs(delta).max() <= np.radians(45.0) + 1e-7


def test_ship_trajectory_is_earth_bound_and_starts_in_steady_state():
    model = ship({}, earth=True)
    t = np.arange(0, 101) / 5.0
    traj = model.trajectory(t)
    linear = model.linear_response(t[:1])[0]
    assert traj.extras["roll_rad"][0] == pytest.approx(linear[0], abs=1e-12)
    assert traj.extras["gimbal_angle_rad"][0] == pytest.approx(linear[4], abs=1e-15)
    # Afloat: the accelerometer reads about +g up (heave and roll add small oscillations).
    g = np.linalg.norm(traj.environment.gravity_w)
    assert np.mean(traj.specific_force_b[:, 2]) == pytest.approx(g, rel=1e-2)
    assert np.abs(traj.omega_b[:, 2].mean()) < 1e-3


# -- spacecraft -----------------------------------------------------------------------------------


def spacecraft(**cmg):
    data = {"kind": "spacecraft-cmg", "duration_s": 120.0, "rate_hz": 10.0}
    if cmg:
        data["cmg"] = cmg
    return scenario_from_dict(data).spec.model()


def test_slew_reaches_the_commanded_attitude_and_conserves_total_angular_momentum():
    # Non-zero initial gimbal angles: the CMGs start with momentum, so H ≠ 0 is a real constraint.
    model = spacecraft(initial_gimbal_deg=[20.0, -10.0, 35.0, 5.0])
    t = np.arange(0, 1201) / 10.0
    sol = model.solve(t)
    traj = model.trajectory(t)
    h_world = traj.extras["angular_momentum_w"]
    h0 = np.linalg.norm(h_world[0])
    assert h0 > 10.0
    assert np.abs(h_world - h_world[0]).max() <= sol.n_steps * 1e-10 * h0
    error = traj.extras["attitude_error_rad"]
    assert error[t < model.start].max() < 1e-9  # holds attitude before the slew
    # Linear closed loop θ̈ + c θ̇ + (k/2) θ = 0: envelope θ0/sqrt(1 − ζ²) exp(−ζ ω_n (t − t_start)).
    zeta, wn = model.c / (2 * np.sqrt(model.k / 2)), np.sqrt(model.k / 2)
    envelope = np.radians(60.0) / np.sqrt(1 - zeta**2) * np.exp(-zeta * wn * (t[-1] - model.start))
    assert error[-1] <= 10 * envelope  # stated tolerance: ten times the linear envelope (3e-4° here)
    assert np.degrees(error[-1]) < 1e-3
    assert np.all(traj.specific_force_b == 0.0)  # free fall


def test_steering_respects_the_gimbal_rate_limit():
    model = spacecraft(gimbal_rate_limit_deg_s=5.0)
    t = np.arange(0, 601) / 10.0
    traj = model.trajectory(t)
    assert np.abs(traj.extras["gimbal_rates_rad_s"]).max() <= np.radians(5.0) * (1 + 1e-12)


# -- configs --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "data, key",
    [
        (
            {"kind": "ship", "duration_s": 1, "rate_hz": 1, "stabiliser": {"spin_rate_rpm": 1}},
            "stabiliser.spin_rate_rpm",
        ),
        ({"kind": "ship", "duration_s": 1, "rate_hz": 1, "waves": {"components": 2.5}}, "waves.components"),
        ({"kind": "ship", "duration_s": 1, "rate_hz": 1, "ship": {"gm_m": -1}}, "ship.gm_m"),
        ({"kind": "ship", "duration_s": 1, "rate_hz": 1, "seed": "7"}, "seed"),
        ({"kind": "spacecraft-cmg", "duration_s": 1, "rate_hz": 1, "slew": {"angle_deg": 200}}, "slew.angle_deg"),
        (
            {"kind": "spacecraft-cmg", "duration_s": 1, "rate_hz": 1, "spacecraft": {"inertia_kgm2": [1, 1, 5]}},
            "spacecraft.inertia_kgm2",
        ),
        (
            {"kind": "spacecraft-cmg", "duration_s": 1, "rate_hz": 1, "cmg": {"initial_gimbal_deg": [0, 0, 0]}},
            "cmg.initial_gimbal_deg[3]",
        ),
    ],
)
def test_bad_keys_raise_config_error_naming_the_key(data, key):
    with pytest.raises(ConfigError) as err:
        scenario_from_dict(data, name="bad.toml")
    assert err.value.key == key
    assert f"key '{key}'" in str(err.value) and "bad.toml" in str(err.value)


@pytest.mark.parametrize("name", ["ship_waves", "ship_waves_stabilised", "spacecraft_slew"])
def test_config_file_loads_and_simulates_a_short_span(name):
    scenario = load_scenario(name)
    assert scenario.description
    traj = scenario.simulate(duration=2.0)
    assert len(traj) == int(round(2.0 * scenario.rate_hz)) + 1
    for value in (traj.q_wb, traj.omega_b, traj.alpha_b, traj.specific_force_b, traj.pos_w, traj.vel_w):
        assert np.all(np.isfinite(value))
    if scenario.kind == "ship":
        # Heave obeys m z̈ = −C (z − η) − c ż on top of buoyancy balancing weight: the non-gravitational
        # force m R_wb f_b has the vertical part m g − ρ g A_wp (z − η) − 2ζ √(C m) ż at every sample
        # (ρ = 1025 kg/m³, sea water), to the round-off of its largest term.
        hull, g = scenario.spec.ship, np.linalg.norm(traj.environment.gravity_w)
        m = hull.displacement_t * 1e3
        c_heave = 1025.0 * g * hull.waterplane_area_m2
        damping = 2 * hull.heave_damping_ratio * np.sqrt(c_heave * m)
        z, z_dot, eta = traj.pos_w[:, 2], traj.vel_w[:, 2], traj.extras["wave_elevation_m"]
        force = m * quat_rotate(traj.q_wb, traj.specific_force_b)[:, 2]
        expected = m * g - c_heave * (z - eta) - damping * z_dot
        np.testing.assert_allclose(force, expected, rtol=0, atol=16 * EPS * np.abs(force).max())
    else:
        # In free space with no momentum in its wheels the spacecraft rests until the slew starts: attitude,
        # rate and specific force exactly as at the start. Through the slew, the CMGs only move momentum
        # about: the total L_w = R_wb (I ω_b + h_b) stays at its initial 0 (no external torque), to the
        # solver's error e (twice its distance from a 1000 times tighter solve), which moves L_w by at most
        # |I| e_ω + e_h + 2 e_q |I ω + h|.
        spec = scenario.spec
        at_rest = traj.t < spec.slew.start_s
        assert np.all(traj.q_wb[at_rest] == traj.q_wb[0]) and not traj.omega_b[at_rest].any()
        assert not traj.specific_force_b.any()
        t = scenario.times(duration=spec.slew.start_s + 6.0)
        slew, tight = spec.model().trajectory(t), spec.model().trajectory(t, rtol=1e-13)
        inertia = np.diag(spec.spacecraft.inertia_kgm2)
        body = slew.omega_b @ inertia.T + slew.extras["cmg_momentum_b"]
        momentum = quat_rotate(slew.q_wb, body)
        err = lambda x, y: 2 * np.abs(x - y).max()
        e_w, e_h = err(slew.omega_b, tight.omega_b), err(slew.extras["cmg_momentum_b"], tight.extras["cmg_momentum_b"])
        scale = np.linalg.norm(body, axis=1).max()
        bound = np.abs(inertia).max() * e_w + e_h + 2 * err(slew.q_wb, tight.q_wb) * scale + 16 * EPS * scale
        assert np.abs(slew.omega_b).max() > 0.01  # the slew is under way
        assert np.abs(momentum - momentum[0]).max() <= bound, (np.abs(momentum - momentum[0]).max(), bound)


def test_stabilised_file_is_the_same_sea_as_the_bare_one():
    bare, stab = load_scenario("ship_waves").spec, load_scenario("ship_waves_stabilised").spec
    assert bare.stabiliser is None and stab.stabiliser is not None
    assert (bare.seed, bare.waves, bare.ship, bare.site) == (stab.seed, stab.waves, stab.ship, stab.site)

"""The drop: contact impulses against the closed forms of Newton's restitution law, the half-sine pulse,
settling, and the config.

Closed forms (body falling flat from rest, no Earth rotation): it lands at ``v = sqrt(2 g h)`` with
``h`` the fall of its lowest face; an ideal impulse ``J = (1 + e) m v`` sends it back at ``e v``; the k-th
bounce rises ``e^(2k) h``. With a half-sine pulse of duration ``τ`` the same ``J`` is spread over ``τ``
while gravity keeps pulling: the box leaves at ``e v − g τ``.
"""

import numpy as np
import pytest

from gyroemu.dynamics import ConfigError, load_scenario, scenario_from_dict
from gyroemu.dynamics.body_kernels import rotation_matrix
from gyroemu.dynamics.impact import contact_impulse
from gyroemu.dynamics.inertia import box
from gyroemu.dynamics.rigid_body import P, contact_mass_matrix

EPS = np.finfo(float).eps


def drop(contact, initial=None, duration=1.0, rate_hz=1000.0, earth=False):
    data = {
        "kind": "drop",
        "duration_s": duration,
        "rate_hz": rate_hz,
        "site": {"earth_rotation": earth},
        "contact": contact,
        "initial": initial or {"height_m": 0.5, "rpy_deg": [0, 0, 0], "omega_b": [0, 0, 0]},
    }
    return scenario_from_dict(data).spec.model()


def test_flat_drop_rebounds_with_e_times_the_impact_speed():
    e = 0.6
    model = drop({"restitution": e, "friction": 0.3, "pulse_duration_s": 0.0, "rest_speed_m_s": 0.02})
    t = np.arange(0, 1001) / 1000.0
    sol = model.solve(t)
    g = model.gravity
    fall = 0.5 - 0.5 * model.size[2]  # centre of mass height minus half the thickness
    v_impact = np.sqrt(2 * g * fall)
    (t1, before, after), *later = sol.jumps
    assert t1 == pytest.approx(np.sqrt(2 * fall / g), rel=1e-12)
    v_before, v_after = before[P] / model.body.mass, after[P] / model.body.mass
    assert v_before[2] == pytest.approx(-v_impact, rel=1e-12)
    assert v_after[2] == pytest.approx(e * v_impact, rel=1e-12)  # e · v_impact
    np.testing.assert_allclose(model.impulses[0][1], [0, 0, (1 + e) * model.body.mass * v_impact], rtol=1e-12)
    # Landing flat: the contact point is the face centre, no torque, no spin.
    assert np.abs(model.body.omega_b(sol.y)).max() < 1e-12
    # Successive bounces: speeds e^k v, times between them 2 e^k v / g.
    impacts = [(tj, b) for tj, b, _ in sol.jumps if model.settling is None or tj < model.settling.t]
    speeds = np.array([-b[P][2] / model.body.mass for _, b in impacts[:4]])
    np.testing.assert_allclose(speeds, v_impact * e ** np.arange(speeds.size), rtol=1e-9)
    gaps = np.diff([tj for tj, _ in impacts[:4]])
    np.testing.assert_allclose(gaps, 2 * v_impact * e ** np.arange(1, gaps.size + 1) / g, rtol=1e-9)


def test_half_sine_pulse_delivers_the_same_impulse_as_a_finite_shock():
    e, tau = 0.5, 0.002
    model = drop({"restitution": e, "friction": 0.0, "pulse_duration_s": tau}, duration=0.5, rate_hz=20000.0)
    t = np.arange(0, 10001) / 20000.0
    traj = model.trajectory(t)
    g = model.gravity
    fall = 0.5 - 0.5 * model.size[2]
    v_impact = np.sqrt(2 * g * fall)
    t_c, j, _ = model.pulses[0]
    assert j[2] == pytest.approx((1 + e) * model.body.mass * v_impact, rel=1e-12)
    # Velocity at the end of the pulse: −v + J/m − g τ = e v − g τ (the pulse's ∫F dt = J exactly).
    after = traj.vel_w[np.searchsorted(t, t_c + tau)]
    t_after = t[np.searchsorted(t, t_c + tau)]
    expected = e * v_impact - g * (t_after - t_c)
    assert after[2] == pytest.approx(expected, abs=1e-9)
    # Peak specific force: π/2 · J/(m τ), seen by the sample nearest the pulse's middle.
    peak = np.pi / 2 * j[2] / (model.body.mass * tau)
    f = traj.specific_force_b[:, 2]
    sampled_peak = f[(t >= t_c) & (t <= t_c + tau)].max()
    assert peak * np.cos(np.pi * (t[1] - t[0]) / (2 * tau)) <= sampled_peak <= peak
    # Before the contact the box falls freely: the accelerometer reads zero.
    assert np.abs(traj.specific_force_b[t < t_c]).max() < 1e-12


def test_contact_impulse_follows_newtons_law_and_never_adds_energy():
    rng = np.random.default_rng(5)
    m = 0.3
    inertia_inv = np.linalg.inv(box(m, 0.1, 0.06, 0.02))
    for _ in range(200):
        q = rng.normal(size=4)
        r = rotation_matrix(q / np.linalg.norm(q))
        iw_inv = r @ inertia_inv @ r.T
        lever = r @ (np.array([0.05, 0.03, 0.01]) * rng.choice([-1, 1], size=3))
        u = rng.normal(size=3)
        u[2] = -abs(u[2]) - 0.1  # closing
        e, mu = rng.uniform(0, 1), rng.choice([0.0, rng.uniform(0, 1)])
        j = contact_impulse(m, iw_inv, lever, u, e, mu)
        k = contact_mass_matrix(m, iw_inv, lever)
        u_after = u + k @ j
        assert j[2] > 0  # the ground pushes
        assert np.hypot(j[0], j[1]) <= mu * j[2] * (1 + 1e-9) + 1e-15  # Coulomb cone
        # Kinetic energy change of the body: J·(u + ½ K J) ≤ 0.
        assert j @ (u + 0.5 * k @ j) <= 1e-12 * (j @ j)
        assert u_after[2] == pytest.approx(-e * u[2], rel=1e-9)  # u⁺_n = −e u_n in every branch
        if 0.0 < np.hypot(j[0], j[1]) < mu * j[2] * (1 - 1e-9):
            np.testing.assert_allclose(u_after, [0, 0, -e * u[2]], atol=1e-9)  # sticking: slip stopped


def test_tumbling_drop_bounces_settles_and_then_reads_gravity():
    scenario = load_scenario("drop_impact")
    model = scenario.spec.model()
    t = scenario.times()
    traj = model.trajectory(t)
    assert model.settling is not None and model.settling.t < t[-1]
    assert len(model.pulses) >= 3
    assert model.settling.tilt < np.radians(5.0)
    settled = t >= max(model.settling.slide_end, model.settling.spin_end)
    g = model.gravity
    # Lying still on a face: |f| = g along a body axis, rotation = the Earth's only.
    f = traj.specific_force_b[settled]
    np.testing.assert_allclose(np.linalg.norm(f, axis=1), g, rtol=1e-9)
    assert np.abs(np.abs(f).max(axis=1) - g).max() < 1e-9 * g
    np.testing.assert_allclose(traj.omega_b[settled], np.broadcast_to(traj.omega_b[-1], f.shape), atol=1e-12)
    assert np.linalg.norm(traj.omega_b[-1]) == pytest.approx(np.linalg.norm(traj.environment.earth_rate_w), rel=1e-6)
    assert traj.pos_w[-1, 2] == pytest.approx(0.5 * model.size[np.argmax(np.abs(f[-1]))], abs=1e-12)
    # Never below the ground by more than a pulse's penetration: v τ.
    assert traj.pos_w[:, 2].min() > 0.5 * model.size.min() - 5.0 * model.pulse_duration
    np.testing.assert_allclose(np.linalg.norm(traj.q_wb, axis=1), 1.0, atol=1e-12)


def test_ideal_impulses_are_reported_per_sample_interval():
    model = drop(
        {"restitution": 0.5, "pulse_duration_s": 0.0},
        initial={"height_m": 0.4, "rpy_deg": [15, -25, 40], "omega_b": [3, 1, -2]},
        duration=1.5,
    )
    t = np.arange(0, 1501) / 1000.0
    traj = model.trajectory(t)
    total = np.sum([j for _, j in model.impulses], axis=0)
    np.testing.assert_allclose(traj.extras["contact_impulse_w"].sum(axis=0), total, rtol=1e-12)
    energy = [model.body.kinetic_energy(a) - model.body.kinetic_energy(b) for _, b, a in model.solve(t).jumps]
    assert max(energy[: len(model.impulses)]) <= 1e-12  # no impulse adds energy


@pytest.mark.parametrize(
    "contact, initial, key",
    [
        ({"restitution": 1.5}, {}, "contact.restitution"),
        ({"pulse_width_s": 0.001}, {}, "contact.pulse_width_s"),
        ({}, {"height": 1.0}, "initial.height"),
        ({"friction": -0.1}, {}, "contact.friction"),
    ],
)
def test_bad_keys_raise_config_error_naming_the_key(contact, initial, key):
    data = {"kind": "drop", "duration_s": 1, "rate_hz": 100, "contact": contact, "initial": initial}
    with pytest.raises(ConfigError) as err:
        scenario_from_dict(data, name="drop.toml")
    assert err.value.key == key and "drop.toml" in str(err.value)


def test_a_box_starting_in_the_ground_is_refused():
    data = {"kind": "drop", "duration_s": 1, "rate_hz": 2e4, "initial": {"height_m": 0.01, "rpy_deg": [45, 0, 0]}}
    with pytest.raises(ConfigError, match="below the ground") as err:
        scenario_from_dict(data, name="drop.toml")
    assert err.value.key == "initial.height_m"


def test_a_truth_too_slow_for_its_contact_pulses_is_refused():
    """The sensors rebuild the force between the truth's samples: a 1 ms pulse sampled twice (2 kHz)
    read 14 % of its impulse short. A file, or a rate asked of ``simulate``, below 20 samples a pulse is
    refused naming ``rate_hz``; ideal impulses (no pulse) take any rate."""
    data = {"kind": "drop", "duration_s": 1, "rate_hz": 2000}
    with pytest.raises(ConfigError, match="20000 Hz") as err:
        scenario_from_dict(data, name="drop.toml")
    assert err.value.key == "rate_hz"
    with pytest.raises(ConfigError, match="20000 Hz") as err:
        load_scenario("drop_impact").simulate(duration=0.1, rate_hz=2000.0)
    assert err.value.key == "rate_hz"
    scenario_from_dict({**data, "contact": {"pulse_duration_s": 0.0}}).simulate(duration=0.1)


def test_an_ideal_accelerometer_reads_each_intervals_mean_force_through_a_contact():
    """An ideal accelerometer reads the mean specific force over each sample interval. Through the first
    contact (a 1 ms half-sine pulse, peak P ≈ 2,700 m/s²) a 1 kHz one measuring the shipped truth
    (20 kHz) reads the means of a ten times finer truth (trapezoids of 200 kHz samples, whose error is
    4·10⁻⁵ of the impulse) within the error of rebuilding a half-sine from 20 samples: h² max|f''| / 8 =
    (π/20)² P / 8, 0.31 % of P (at the shipped file's former 2 kHz, 38 %)."""
    from gyroemu.sensors.presets import device_from_dict

    scenario = load_scenario("drop_impact")
    fine = scenario.simulate(duration=0.5, rate_hz=200_000.0)
    per = 200  # fine samples per 1 ms interval
    f = fine.specific_force_b
    means = np.array([np.trapezoid(f[per * k : per * k + per + 1], axis=0) / per for k in range((len(f) - 1) // per)])
    ideal = {"description": "ideal", "rate_hz": 1000, "gyro": {"mechanism": {"kind": "ideal"}}}
    samples = device_from_dict(ideal).measure(scenario.simulate(duration=0.5))
    k = np.round(samples.t_true * 1000).astype(int) - 1  # the interval (k/1000, (k+1)/1000] of each sample
    peak = np.linalg.norm(means, axis=1).max()
    assert peak > 1000.0  # the contact is inside the span
    assert np.abs(samples.accel - means[k]).max() <= (np.pi / 20) ** 2 / 8 * peak


def test_drop_config_file_loads_and_simulates_a_short_span():
    scenario = load_scenario("drop_impact")
    assert scenario.description
    t = scenario.times(duration=0.5)
    model = scenario.spec.model()
    traj = model.trajectory(t)  # what scenario.simulate(duration=0.5) returns, with the model's contact history
    assert len(traj) == 10001  # 0.5 s at 20 kHz
    assert np.all(np.isfinite(traj.specific_force_b))
    assert np.abs(traj.specific_force_b[:100]).max() < 1e-9  # free fall until the first contact
    # Free flight, up to the first contact: no specific force; torque-free, so Euler's equations
    # I α + ω × I ω = 0 hold at every sample to round-off (I of the box, m/12 (b² + c², a² + c², a² + b²)),
    # and |L| = |I ω| and E = ½ ω·I ω keep their initial values to the solver's error: twice the distance to a
    # 1000 times tighter solve bounds e_ω, which moves |L| by ≤ √3 |I| e_ω and E by ≤ √3 |I ω| e_ω.
    assert model.pulses and 0.3 < model.pulses[0][0] < 0.5  # a 1 m fall lasts √(2 h/g) ≈ 0.45 s
    flight = t < model.pulses[0][0]
    body = scenario.spec.body
    a, b, c = body.size_m
    inertia = body.mass_kg / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
    g = np.linalg.norm(traj.environment.gravity_w)
    assert np.abs(traj.specific_force_b[flight]).max() <= 16 * EPS * g
    w, alpha = traj.omega_b[flight], traj.alpha_b[flight]
    i_w = w @ inertia.T
    euler = alpha @ inertia.T + np.cross(w, i_w)
    scale = np.abs(alpha @ inertia.T).max() + np.abs(np.cross(w, i_w)).max()
    assert np.abs(euler).max() <= 16 * EPS * scale
    tight = scenario.spec.model().trajectory(t[flight], rtol=1e-13)
    e_w = 2 * np.abs(w - tight.omega_b).max()
    momentum, energy = np.linalg.norm(i_w, axis=1), 0.5 * np.sum(w * i_w, axis=1)
    bound = 2 * np.sqrt(3) * e_w
    assert np.abs(momentum - momentum[0]).max() <= bound * np.abs(inertia).max() + 16 * EPS * momentum[0]
    assert np.abs(energy - energy[0]).max() <= bound * momentum.max() + 16 * EPS * energy[0]

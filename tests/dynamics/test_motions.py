"""Prescribed motions (gyroemu.dynamics.motions): closed forms against finite differences and against theory.

The kinematic checks (:func:`assert_kinematics`) difference the produced samples and compare with the
produced derivatives. Their tolerances are the central-difference truncation bounds

    |(f(t+h) − f(t−h))/2h − f′(t)| ≤ h²/6 · max|f‴|
    |(f(t+h) − 2f(t) + f(t−h))/h² − f″(t)| ≤ h²/12 · max|f⁗|

with ``max|f‴|``, ``max|f⁗|`` bounded from each motion's amplitudes and frequencies, plus round-off
(:func:`roundoff`). Test grids are ``t0 + k h`` with ``h`` a power of two and ``t0`` an integer, so the
times themselves are exact.
"""

from __future__ import annotations

import numpy as np
import pytest
from kinematics_checks import EPS, assert_kinematics, rotation_bounds, step_bound, uniform_times
from scipy.integrate import simpson
from scipy.special import j1

from gyroemu.dynamics import (
    EARTH_RATE,
    KINDS,
    ConfigError,
    list_scenarios,
    load_scenario,
    normal_gravity,
    scenario_from_dict,
)
from gyroemu.dynamics.motion_kernels import TimeGrid, smooth_step
from gyroemu.dynamics.motions import (
    ConingSpec,
    OscillationSpec,
    RateTableSpec,
    ScullingSpec,
    StaticSpec,
)
from gyroemu.dynamics.prescribed import quat_from_rpy_deg
from gyroemu.dynamics.rotation import (
    quat_angle,
    quat_conjugate,
    quat_rotate,
)

SITE = {"latitude_deg": 48.0, "height_m": 500.0}


def spec(kind_dict):
    """A spec from a scenario dict, validated as a file would be."""
    base = {"duration_s": 10.0, "rate_hz": 100.0, "site": SITE}
    return scenario_from_dict({**base, **kind_dict}).spec


def earth_rate_body(q_wb, latitude_deg=SITE["latitude_deg"]):
    lat = np.radians(latitude_deg)
    return quat_rotate(quat_conjugate(q_wb), EARTH_RATE * np.array([0.0, np.cos(lat), np.sin(lat)]))


# --------------------------------------------------------------------------------------------------
# Building blocks
# --------------------------------------------------------------------------------------------------


def test_time_grid_angle_addition_is_as_exact_as_direct_evaluation():
    rate = 1000.0
    k = np.arange(200_001)
    t = k / rate  # as Scenario.times makes them
    grid = TimeGrid(t)
    assert grid.uniform
    omega, phase = 2 * np.pi * 13.7, 0.3
    c, s = grid.cos_sin(omega, phase)
    # Reference: the exact phase ω k / rate + φ (at the float ω, φ) in extended precision.
    exact = np.longdouble(omega) * (k.astype(np.longdouble) / np.longdouble(rate)) + np.longdouble(phase)
    direct = omega * t + phase
    err_fast = max(np.abs(c - np.cos(exact)).max(), np.abs(s - np.sin(exact)).max())
    err_direct = max(np.abs(np.cos(direct) - np.cos(exact)).max(), np.abs(np.sin(direct) - np.sin(exact)).max())
    # Both lose about one ulp of the largest phase: the rounding of t = k/rate and of ω t + φ.
    bound = 1.5 * EPS * np.abs(direct).max() + 8 * EPS
    assert err_direct <= bound
    assert err_fast <= bound


def test_sum_of_sines_uniform_matches_direct():
    rng = np.random.default_rng(5)
    a, w, p = rng.random((3, 4)), rng.uniform(0.1, 20, (3, 4)), rng.uniform(0, 6, (3, 4))
    t = np.arange(10_000) / 250.0
    fast = TimeGrid(t).sum_of_sines(a, w, p)
    direct = TimeGrid(t[::-1]).sum_of_sines(a, w, p)[:, :, ::-1]  # a reversed grid is evaluated directly
    assert TimeGrid(t).uniform and not TimeGrid(t[::-1]).uniform
    scale = (a * w ** np.arange(3)[:, None, None]).sum(-1)  # Σ A ωⁿ per derivative and channel
    np.testing.assert_array_less(np.abs(fast - direct).max(-1), 64 * EPS * scale * (1 + w.max() * t.max()))


def test_smooth_step_is_a_c5_step():
    u = np.array([-1.0, 0.0, 0.25, 0.5, 0.75, 1.0, 2.0])
    s, s1, s2, s3, area = smooth_step(u, derivatives=3, integral=True)
    # At u = ¼, ½, ¾: sin 2πu = 1, 0, −1 and cos 2πu = 0, −1, 0 in the closed forms.
    np.testing.assert_allclose(
        s, [0, 0, 0.25 - 22 / (30 * np.pi), 0.5, 0.75 + 22 / (30 * np.pi), 1, 1], rtol=0, atol=4 * EPS
    )
    np.testing.assert_allclose(s1, [0, 0, 0.4, 3.2, 0.4, 0, 0], rtol=0, atol=4 * EPS)  # (16/5) sin⁶ πu
    assert np.all(s2[[0, 1, 5, 6]] == 0) and np.all(s3[[0, 1, 5, 6]] == 0)
    # I(½) = ⅛ − (1 − c)(109 − 23c + 4c²)/(360π²) with c = −1
    half = 0.125 - 2 * 136 / (360 * np.pi**2)
    np.testing.assert_allclose(area[[0, 1, 3, 5, 6]], [0, 0, half, 0.5, 1.5], rtol=0, atol=4 * EPS)
    # I against Simpson's rule on S: error ≤ (½) h⁴/180 max|S⁗| with h = 1/40000.
    fine = np.linspace(0, 0.5, 20001)
    h = fine[1] - fine[0]
    assert simpson(smooth_step(fine, derivatives=0)[0], x=fine) == pytest.approx(
        half, abs=0.5 * h**4 / 180 * step_bound(4) + 1e-15
    )


# --------------------------------------------------------------------------------------------------
# static
# --------------------------------------------------------------------------------------------------


def test_static_level_bench_reads_earth_rate_and_plus_g():
    s = spec({"kind": "static", "attitude": {"rpy_deg": [0.0, 0.0, 30.0]}})
    traj = s.trajectory(uniform_times(0.0, 2.0))
    lat = np.radians(SITE["latitude_deg"])
    # Level, body x 30° north of east:
    # R_bw Ω (0, cos φ, sin φ) = Ω (cos φ sin 30°, cos φ cos 30°, sin φ).
    expected = EARTH_RATE * np.array(
        [np.cos(lat) * np.sin(np.radians(30)), np.cos(lat) * np.cos(np.radians(30)), np.sin(lat)]
    )
    np.testing.assert_allclose(
        traj.omega_b, np.broadcast_to(expected, traj.omega_b.shape), rtol=0, atol=4 * EPS * EARTH_RATE
    )
    g = normal_gravity(lat, SITE["height_m"])
    np.testing.assert_allclose(
        traj.specific_force_b, np.broadcast_to([0, 0, g], (len(traj), 3)), rtol=0, atol=8 * EPS * g
    )
    assert not traj.alpha_b.any() and not traj.pos_w.any() and not traj.vel_w.any()
    assert_kinematics(traj, rotation_bounds(0, 0, 0, 0))


def test_static_tilted_bench_reads_rotated_gravity():
    s = spec({"kind": "static", "attitude": {"rpy_deg": [10.0, -20.0, 200.0]}})
    traj = s.trajectory(uniform_times(0.0, 1.0))
    q = quat_from_rpy_deg([10.0, -20.0, 200.0])
    g = normal_gravity(np.radians(SITE["latitude_deg"]), SITE["height_m"])
    np.testing.assert_allclose(traj.specific_force_b[0], quat_rotate(quat_conjugate(q), [0, 0, g]), atol=8 * EPS * g)
    np.testing.assert_allclose(traj.omega_b[-1], earth_rate_body(q), atol=4 * EPS * EARTH_RATE)


# --------------------------------------------------------------------------------------------------
# rate-table
# --------------------------------------------------------------------------------------------------


def test_rate_table_constant_reads_table_rate_plus_earth_rate():
    rate = np.radians(37.0)
    s = spec({"kind": "rate-table", "constant": {"rate_deg_s": 37.0}})
    traj = s.trajectory(uniform_times(3.0, 8.0))
    # Level table, no mounting rotation: ω_b = (0, 0, r) + R_bw Ω.
    np.testing.assert_allclose(traj.omega_b, [0, 0, rate] + earth_rate_body(traj.q_wb), rtol=0, atol=8 * EPS * rate)
    np.testing.assert_allclose(traj.extras["table_angle_rad"], rate * traj.t, rtol=4 * EPS)
    assert_kinematics(traj, rotation_bounds(rate, 0, 0, 0))


def test_rate_table_mounting_and_tilted_axis():
    # Body mounted rolled by 90°: its y axis lies along the table axis. Base pitched by −90°:
    # Ry(−90°) e_z = −e_x, the axis points west, and the body's y axis with it.
    rate = np.radians(-15.0)
    s = spec(
        {
            "kind": "rate-table",
            "table": {"mount_rpy_deg": [90.0, 0.0, 0.0], "base_rpy_deg": [0.0, -90.0, 0.0]},
            "constant": {"rate_deg_s": -15.0, "initial_angle_deg": 40.0},
        }
    )
    traj = s.trajectory(uniform_times(0.0, 4.0))
    np.testing.assert_allclose(
        traj.omega_b - earth_rate_body(traj.q_wb), np.broadcast_to([0, rate, 0], (len(traj), 3)), atol=8 * EPS
    )
    y_world = quat_rotate(traj.q_wb, [0.0, 1.0, 0.0])
    np.testing.assert_allclose(y_world, np.broadcast_to([-1.0, 0, 0], y_world.shape), rtol=0, atol=8 * EPS)
    assert_kinematics(traj, rotation_bounds(abs(rate), 0, 0, 0))


def test_rate_table_lever_arm_feels_centripetal_acceleration():
    rate, radius = np.radians(90.0), 0.25
    s = spec({"kind": "rate-table", "table": {"lever_arm_m": [radius, 0.0, 0.1]}, "constant": {"rate_deg_s": 90.0}})
    traj = s.trajectory(uniform_times(0.0, 4.0))
    m = s.world_motion(traj.t)
    # Uniform circular motion: |a| = r ω², pointing at the axis; |v| = r ω.
    np.testing.assert_allclose(np.linalg.norm(m.acc_w, axis=1), radius * rate**2, rtol=16 * EPS)
    np.testing.assert_allclose(
        m.acc_w, -(rate**2) * (m.pos_w * [1.0, 1.0, 0.0]), rtol=0, atol=16 * EPS * radius * rate**2
    )
    np.testing.assert_allclose(m.pos_w[:, 2], 0.1, rtol=0, atol=4 * EPS)
    assert_kinematics(traj, rotation_bounds(rate, 0, 0, 0, p3=radius * rate**3, p4=radius * rate**4))


STEPS = {"rates_deg_s": [10.0, -25.0, 0.0, 60.0], "dwell_s": [2.0, 1.5, 1.0, 2.0], "max_accel_deg_s2": 40.0}


def test_rate_table_steps_reach_each_rate_and_dwell():
    s = spec({"kind": "rate-table", "steps": STEPS})
    start, angle, rate, accel = s.steps.schedule()
    traj = s.trajectory(uniform_times(0.0, start[-1] + 1.0))
    table_rate = traj.extras["table_rate_rad_s"]
    a_max = np.radians(STEPS["max_accel_deg_s2"])
    # Dwell k begins when rate k is reached and lasts dwell_s[k]: find it in the schedule.
    for target, dwell in zip(np.radians(STEPS["rates_deg_s"]), STEPS["dwell_s"]):
        k = np.flatnonzero((rate == target) & (accel == 0))[0]
        assert start[k + 1] - start[k] == pytest.approx(dwell, rel=4 * EPS)
        inside = (traj.t > start[k]) & (traj.t < start[k + 1])
        np.testing.assert_allclose(table_rate[inside], target, rtol=0, atol=16 * EPS * a_max * traj.t.max())
        np.testing.assert_allclose(
            traj.omega_b[inside] - earth_rate_body(traj.q_wb[inside]),
            np.outer(table_rate[inside], [0, 0, 1]),
            rtol=0,
            atol=16 * EPS,
        )
    # Ramps take |Δω| / a_max at ±a_max; the rate is continuous at every corner.
    ramps = accel != 0
    np.testing.assert_allclose(np.abs(accel[ramps]), a_max)
    np.testing.assert_allclose(np.diff(start)[ramps[:-1]], np.abs(np.diff(rate))[ramps[:-1]] / a_max, rtol=8 * EPS)
    w1 = np.abs(np.radians(STEPS["rates_deg_s"])).max()
    for corner in start[1:]:
        before, after = s.steps.angle(np.array([corner - 1e-9, corner + 1e-9]))[1]
        assert abs(after - before) <= 2e-9 * a_max + 8 * EPS * w1  # |Δω| ≤ a_max · 2δ
    # Away from the corners the angle is quadratic in time.
    assert_kinematics(traj, rotation_bounds(w1, a_max, 0, 0), breakpoints=start[1:])


def test_rate_table_tumble_dwells_at_each_face():
    faces = [
        [0.0, 0.0, 0.0],
        [180.0, 0.0, 0.0],
        [90.0, 0.0, 0.0],
        [-90.0, 0.0, 0.0],
        [0.0, -90.0, 0.0],
        [0.0, 90.0, 0.0],
    ]
    up_axis = [[0, 0, 1], [0, 0, -1], [0, 1, 0], [0, -1, 0], [1, 0, 0], [-1, 0, 0]]  # body axis pointing up
    dwell, move = 3.0, 2.0
    s = spec({"kind": "rate-table", "tumble": {"rpy_deg": faces, "dwell_s": dwell, "move_s": move}})
    traj = s.trajectory(uniform_times(0.0, 6 * (dwell + move)))
    g = normal_gravity(np.radians(SITE["latitude_deg"]), SITE["height_m"])
    for k, (rpy, up) in enumerate(zip(faces, up_axis)):
        inside = (traj.t >= k * (dwell + move)) & (traj.t <= k * (dwell + move) + dwell)
        assert quat_angle(traj.q_wb[inside], quat_from_rpy_deg(rpy)).max() <= 8 * EPS
        np.testing.assert_allclose(
            traj.omega_b[inside], earth_rate_body(traj.q_wb[inside]), rtol=0, atol=4 * EPS * EARTH_RATE
        )
        np.testing.assert_allclose(
            traj.specific_force_b[inside],
            g * np.broadcast_to(up, (inside.sum(), 3)),
            rtol=0,
            atol=16 * EPS * g,
        )
    # Moves along S(τ/T) by at most φ (here 180°): |ω| ≤ φ max S′/T, |α| ≤ φ max S″/T², ...
    phi = np.linalg.norm(s.tumble.schedule()[1], axis=1).max()
    assert phi == pytest.approx(np.pi)
    w = [phi * step_bound(n) / move**n for n in range(1, 5)]
    assert_kinematics(traj, rotation_bounds(*w))


def test_rate_table_tumble_with_lever_arm():
    r = np.array([0.05, -0.02, 0.03])
    s = spec(
        {
            "kind": "rate-table",
            "table": {"lever_arm_m": r.tolist(), "mount_rpy_deg": [0.0, 0.0, 45.0]},
            "tumble": {
                "rpy_deg": [[0.0, 0.0, 0.0], [0.0, 90.0, 0.0], [30.0, 0.0, 0.0]],
                "dwell_s": 1.0,
                "move_s": 1.5,
            },
        }
    )
    traj = s.trajectory(uniform_times(0.0, 6.0))
    phi, move, radius = (
        np.linalg.norm(s.tumble.schedule()[1], axis=1).max(),
        1.5,
        np.linalg.norm(r),
    )  # largest move
    w = [phi * step_bound(n) / move**n for n in range(1, 6)]
    # Lever arm: p = R r with Ṙ = [ω]× R, so |p⁽ⁿ⁾| ≤ |r| Bₙ(w1, …, wₙ) (complete Bell polynomials).
    p3 = radius * (w[2] + 3 * w[0] * w[1] + w[0] ** 3)
    p4 = radius * (w[3] + 4 * w[0] * w[2] + 3 * w[1] ** 2 + 6 * w[0] ** 2 * w[1] + w[0] ** 4)
    assert_kinematics(traj, rotation_bounds(*w[:4], p3=p3, p4=p4))
    np.testing.assert_allclose(np.linalg.norm(traj.pos_w, axis=1), radius, rtol=8 * EPS)


# --------------------------------------------------------------------------------------------------
# oscillation
# --------------------------------------------------------------------------------------------------


def test_oscillation_rate_and_linear_vibration():
    amp, f, lin, fl = 5.0, 2.0, 5e-4, 10.0
    s = spec(
        {
            "kind": "oscillation",
            "attitude": {"rpy_deg": [0.0, 10.0, 45.0]},
            "angular": {
                "axis_b": [1.0, 1.0, 0.0],
                "amplitude_deg": amp,
                "frequency_hz": f,
                "phase_deg": 30.0,
            },
            "linear": {"amplitude_m": [0.0, lin, lin], "frequency_hz": fl},
        }
    )
    traj = s.trajectory(uniform_times(7.0, 3.0, h=2.0**-12))
    a, w = np.radians(amp), 2 * np.pi * f
    # θ = A sin(ωt + φ) about n_b: |θ⁽ⁿ⁾| ≤ A ωⁿ. Position a sin(ω_l t): |p⁽ⁿ⁾| ≤ |a| ω_lⁿ.
    wl, a_lin = 2 * np.pi * fl, np.sqrt(2) * lin
    assert_kinematics(traj, rotation_bounds(*(a * w**n for n in range(1, 5)), p3=a_lin * wl**3, p4=a_lin * wl**4))
    m = s.world_motion(traj.t)
    theta_dot = a * w * np.cos(w * traj.t + np.radians(30.0))
    np.testing.assert_allclose(
        m.omega_wb_b, np.outer(theta_dot, [1, 1, 0]) / np.sqrt(2), atol=64 * EPS * a * w * (1 + w * 10)
    )


# --------------------------------------------------------------------------------------------------
# coning
# --------------------------------------------------------------------------------------------------

CONE = {"half_angle_deg": 2.0, "frequency_hz": 5.0, "reference_rpy_deg": [20.0, -70.0, 10.0]}


def test_coning_rate_agrees_with_attitude():
    s = spec({"kind": "coning", "coning": CONE})
    traj = s.trajectory(uniform_times(2.0, 1.0, h=2.0**-13))
    theta, om = np.radians(CONE["half_angle_deg"]), 2 * np.pi * CONE["frequency_hz"]
    # |ω| = 2Ω sin(θ/2), |α| = Ω² sin θ, |α̇| = Ω³ sin θ, |α̈| = Ω⁴ sin θ.
    assert_kinematics(traj, rotation_bounds(2 * om * np.sin(theta / 2), *(om**n * np.sin(theta) for n in (2, 3, 4))))


def test_coning_attitude_is_periodic_but_the_rate_integral_is_not_zero():
    """Savage's coning: over a cycle the body returns to its attitude, while
    ∫ω dt = (−2π(1 − cos θ), 0, 0)."""
    theta, f = np.radians(CONE["half_angle_deg"]), CONE["frequency_hz"]
    s = spec({"kind": "coning", "coning": CONE})
    n = 4096
    t = 3.0 + np.arange(n + 1) / (n * f)  # one cycle, exactly 4096 steps
    m = s.world_motion(t)
    assert quat_angle(m.q_wb[0], m.q_wb[-1]) <= 16 * EPS * (1 + 2 * np.pi * f * t[-1])
    # Simpson over the cycle: error ≤ T h⁴/180 · max|ω⁗| = T h⁴/180 · Ω⁴ · Ω sin θ.
    om, h = 2 * np.pi * f, 1 / (n * f)
    integral = simpson(m.omega_wb_b, x=t, axis=0)
    np.testing.assert_allclose(
        integral,
        [-2 * np.pi * (1 - np.cos(theta)), 0, 0],
        rtol=0,
        atol=(1 / f) * h**4 / 180 * om**5 * np.sin(theta) + 64 * EPS * om / f,
    )
    # The body x axis keeps the half-angle to the cone axis (the reference x axis).
    q_ref = quat_from_rpy_deg(CONE["reference_rpy_deg"])
    x_b = quat_rotate(m.q_wb, [1.0, 0, 0])
    np.testing.assert_allclose(x_b @ quat_rotate(q_ref, [1.0, 0, 0]), np.cos(theta), rtol=0, atol=8 * EPS)
    # and sweeps it at the coning rate: its angle about the cone axis goes once round per cycle.
    y_r, z_r = quat_rotate(q_ref, [0, 1.0, 0]), quat_rotate(q_ref, [0, 0, 1.0])
    sweep = np.unwrap(np.arctan2(x_b @ z_r, x_b @ y_r))
    # (atan2 of components of size sin θ: a few ulp / sin θ)
    assert sweep[-1] - sweep[0] == pytest.approx(2 * np.pi, abs=64 * EPS / np.sin(theta))


# --------------------------------------------------------------------------------------------------
# sculling
# --------------------------------------------------------------------------------------------------


def sculling_spec(phase_deg=0.0):
    return spec(
        {
            "kind": "sculling",
            "sculling": {
                "angular_amplitude_deg": 3.0,
                "acceleration_amplitude_m_s2": 4.0,
                "frequency_hz": 8.0,
                "phase_deg": phase_deg,
                "reference_rpy_deg": [0.0, 0.0, 30.0],
            },
        }
    )


def test_sculling_kinematics():
    traj = sculling_spec(25.0).trajectory(uniform_times(1.0, 1.0, h=2.0**-13))
    theta0, om, acc = np.radians(3.0), 2 * np.pi * 8.0, 4.0
    assert_kinematics(traj, rotation_bounds(*(theta0 * om**n for n in range(1, 5)), p3=acc * om, p4=acc * om**2))


@pytest.mark.parametrize("phase_deg", [0.0, 60.0, 90.0])
def test_sculling_rectified_specific_force(phase_deg):
    """Mean body-z specific force (without gravity and Coriolis) over whole cycles: −A J₁(θ0) cos φ."""
    s = sculling_spec(phase_deg)
    f, cycles, per_cycle = 8.0, 5, 400
    t = 2.0 + np.arange(cycles * per_cycle) / (per_cycle * f)
    traj = s.trajectory(t)
    env = traj.environment
    q_bw = quat_conjugate(traj.q_wb)
    sculling_force = traj.specific_force_b - quat_rotate(
        q_bw, 2 * np.cross(env.earth_rate_w, traj.vel_w) - env.gravity_w
    )
    # The sampled mean of a periodic function over whole cycles is exact up to aliased harmonics of
    # order ≥ 400, whose Bessel weights J_n(θ0) are far below round-off.
    expected = -4.0 * j1(np.radians(3.0)) * np.cos(np.radians(phase_deg))
    assert sculling_force[:, 2].mean() == pytest.approx(expected, abs=64 * EPS * 4.0)
    assert sculling_force[:, 0].mean() == pytest.approx(0.0, abs=64 * EPS * 4.0)
    # Small-angle form of sculling theory, ½ A θ0: J₁(x) = x/2 (1 − x²/8 + …), an alternating series.
    theta0 = np.radians(3.0)
    assert expected == pytest.approx(-0.5 * 4.0 * theta0 * np.cos(np.radians(phase_deg)), rel=theta0**2 / 8, abs=1e-15)
    # The body goes nowhere: velocity and position are periodic.
    np.testing.assert_allclose(traj.vel_w[:per_cycle], traj.vel_w[-per_cycle:], atol=1e-13)


# --------------------------------------------------------------------------------------------------
# Config files and errors
# --------------------------------------------------------------------------------------------------

BUILT_IN = [
    s.name
    for s in list_scenarios()
    if KINDS[s.kind].startswith(("gyroemu.dynamics.motions", "gyroemu.dynamics.vehicles"))
]


@pytest.mark.parametrize("name", BUILT_IN)
def test_built_in_scenarios_load_and_simulate(name):
    scenario = load_scenario(name)
    assert scenario.description and len(scenario.description) < 110
    assert 60 <= scenario.duration_s <= 600 and 100 <= scenario.rate_hz <= 1000
    traj = scenario.simulate(duration=2.0)
    assert len(traj) == int(round(2.0 * scenario.rate_hz)) + 1
    for name_ in ("q_wb", "omega_b", "alpha_b", "specific_force_b", "pos_w", "vel_w", "mag_b"):
        assert np.isfinite(getattr(traj, name_)).all()
    np.testing.assert_allclose(np.linalg.norm(traj.q_wb, axis=1), 1.0, atol=4 * EPS)


@pytest.mark.parametrize("name", BUILT_IN)
def test_motion_in_pieces_equals_motion_at_once(name):
    """Evaluated piece by piece (as a stream would, through the evaluator) the motion is the same: no
    kind depends on where its time grid starts. Differences are the round-off of phases up to a few
    thousand rad (16 ulp of 4e3 rad ≈ 1.4e-11 relative)."""
    spec = load_scenario(name).spec
    t = np.arange(30_001) / 500.0
    whole = spec.world_motion(t)
    evaluate = spec.evaluator()
    pieces = [evaluate(t[:12_345]), evaluate(t[12_345:])]
    for field in ("q_wb", "omega_wb_b", "alpha_wb_b", "pos_w", "vel_w", "acc_w"):
        joined = np.concatenate([getattr(p, field) for p in pieces])
        expected = getattr(whole, field)
        np.testing.assert_allclose(joined, expected, rtol=0, atol=1e-10 * max(1.0, np.abs(expected).max()))


@pytest.mark.parametrize(
    "data, key",
    [
        ({"kind": "static", "attitude": {"rpy": [0, 0, 0]}}, "attitude.rpy"),
        ({"kind": "static", "attitude": {"rpy_deg": [0, 0]}}, "attitude.rpy_deg[2]"),  # the missing element
        ({"kind": "static", "site": {"latitude_deg": 95.0}}, "site.latitude_deg"),
        ({"kind": "rate-table", "constant": {"rate_deg_per_s": 10}}, "constant.rate_deg_per_s"),
        ({"kind": "rate-table", "constant": {"rate_deg_s": "10"}}, "constant.rate_deg_s"),
        ({"kind": "rate-table", "steps": {**STEPS, "dwell_s": [1.0]}}, "steps.dwell_s"),
        ({"kind": "rate-table", "steps": {**STEPS, "max_accel_deg_s2": 0}}, "steps.max_accel_deg_s2"),
        ({"kind": "rate-table", "constant": {"rate_deg_s": 1}, "steps": STEPS}, "steps"),
        ({"kind": "rate-table", "tumble": {"rpy_deg": [], "dwell_s": 1, "move_s": 1}}, "tumble.rpy_deg"),
        (
            {"kind": "oscillation", "angular": {"axis_b": [0, 0, 0], "amplitude_deg": 1, "frequency_hz": 1}},
            "angular.axis_b",
        ),
        (
            {"kind": "oscillation", "angular": {"amplitude_deg": 1, "frequency_hz": -1}},
            "angular.frequency_hz",
        ),
        ({"kind": "coning", "coning": {"half_angle_deg": 0, "frequency_hz": 1}}, "coning.half_angle_deg"),
        ({"kind": "coning", "coning": {"half_angle_deg": 1, "frequency_hz": 1}, "spin": 1}, "spin"),
        (
            {"kind": "sculling", "sculling": {"angular_amplitude_deg": 1, "frequency_hz": 1}},
            "sculling.acceleration_amplitude_m_s2",
        ),
    ],
)
def test_bad_keys_name_the_key(data, key):
    with pytest.raises(ConfigError) as err:
        scenario_from_dict({"duration_s": 1.0, "rate_hz": 10.0, **data}, name="bad.toml")
    assert err.value.key == key
    assert "bad.toml" in str(err.value) and key in str(err.value)


def test_rate_table_without_a_mode_says_which_tables():
    with pytest.raises(ConfigError, match=r"\[constant\], \[steps\] or \[tumble\]"):
        scenario_from_dict({"kind": "rate-table", "duration_s": 1.0, "rate_hz": 10.0})


def test_specs_round_trip_through_toml():
    for cls, data in [
        (StaticSpec, {}),
        (RateTableSpec, {"tumble": {"rpy_deg": [[0, 0, 0]], "dwell_s": 1, "move_s": 1}}),
        (OscillationSpec, {"angular": {"amplitude_deg": 1, "frequency_hz": 1}}),
        (ConingSpec, {"coning": CONE}),
        (
            ScullingSpec,
            {"sculling": {"angular_amplitude_deg": 1, "acceleration_amplitude_m_s2": 1, "frequency_hz": 1}},
        ),
    ]:
        spec_ = cls.model_validate({"duration_s": 1.0, "rate_hz": 10.0, **data})
        again = scenario_from_dict(spec_.model_dump(mode="json")).spec
        assert again == spec_

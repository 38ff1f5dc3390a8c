"""Every built-in scenario loads, simulates, and round-trips through its resolved TOML."""

import tomllib

import numpy as np
import pytest
from kinematics_checks import EPS, assert_kinematics, rotation_bounds, uniform_times

from gyroemu.dynamics import (
    EARTH_RATE,
    KINDS,
    ConfigError,
    Trajectory,
    list_scenarios,
    load_scenario,
    scenario_from_dict,
)
from gyroemu.dynamics.config import config_dir
from gyroemu.dynamics.rotation import quat_conjugate, quat_rotate

BUILTIN = sorted(p.stem for p in (config_dir() / "scenarios").glob("*.toml"))
# Kinds integrated by DOP853 (dynamics/integrate.py, default rtol 1e-10): their samples carry the solver's error.
INTEGRATED = {"ship", "spacecraft-cmg"}


def rate_step_corners(steps):
    """Times where a rate-step table's acceleration jumps: it starts at rest at 0, ramps at ±max_accel to
    each rate and dwells there for its dwell time (the [steps] table's documented profile)."""
    t, rate, corners = 0.0, 0.0, [0.0]
    for target, dwell in zip(np.radians(steps.rates_deg_s), steps.dwell_s):
        t += abs(target - rate) / np.radians(steps.max_accel_deg_s2)
        corners += [t, t + dwell]
        t, rate = t + dwell, target
    return corners


def estimated_bounds(traj, keep, tight=None):
    """Derivative bounds for :func:`assert_kinematics` from the trajectory's own derivative channels.

    A difference quotient of n-th order is the n-th derivative at some point of its stencil (mean value
    theorem); between such points the derivative can exceed it by a step's worth of the next one, which a
    factor 2 covers while the samples resolve the motion. So |α̇|, |α̈| come from α_b's differences and
    |p⃛|, |p⁗| from those of the world acceleration a_w = R_wb f_b + g_w − 2 Ω × v_w (the definition of f_b),
    on the stencils ``keep`` (none straddling a corner). A solver's error e in the samples enters a central
    difference as e/h, as a third-derivative bound 6e/h³ would (a second difference: 4e/h², as a
    fourth-derivative bound 48e/h⁴). ``tight``: the same motion solved at a 1000 times tighter tolerance,
    whose difference from ``traj`` is the solver's error to 10⁻³ of itself; twice it bounds e.
    """
    h = traj.t[1] - traj.t[0]
    env = traj.environment
    alpha = traj.alpha_b
    a_w = quat_rotate(traj.q_wb, traj.specific_force_b) + env.gravity_w - 2 * np.cross(env.earth_rate_w, traj.vel_w)

    def rate_of_change(x, order):
        d = np.linalg.norm(np.diff(x, order, axis=0), axis=1) / h**order
        mask = keep[: len(d)] if order == 2 else np.concatenate([keep, keep[-1:]])[: len(d)]
        return 2 * d[mask].max(initial=0.0)

    # rotation_bounds wants the rates relative to the world, ω_wb = ω_b − R_bw Ω: each derivative of the
    # Earth term e is bounded by Ω_E times those of the motion (ė = −ω × e, ë = −α × e + ω × (ω × e), …).
    w1 = np.linalg.norm(traj.omega_b, axis=1).max() + EARTH_RATE
    w2 = np.linalg.norm(alpha, axis=1).max() + EARTH_RATE * w1
    w3 = rate_of_change(alpha, 1) + EARTH_RATE * (w2 + w1**2)
    w4 = rate_of_change(alpha, 2) + EARTH_RATE * (w3 + 3 * w1 * w2 + w1**3)
    bounds = rotation_bounds(w1, w2, w3, w4, rate_of_change(a_w, 1), rate_of_change(a_w, 2))
    if tight is not None:
        err = lambda name: 2 * np.abs(getattr(traj, name) - getattr(tight, name)).max()
        bounds.q3 += 6 * err("q_wb") / h**3
        bounds.w3 += 6 * err("omega_b") / h**3
        bounds.p3 += 6 * err("pos_w") / h**3
        bounds.p4 += 48 * err("pos_w") / h**4
    return bounds


def test_every_kind_has_a_builtin_scenario():
    kinds = {s.kind for s in list_scenarios()}
    assert kinds == set(KINDS)


@pytest.mark.parametrize("name", BUILTIN)
def test_builtin_scenario_simulates_a_short_span(name):
    scenario = load_scenario(name)
    assert scenario.description, "the one-line description is what 'gyroemu scenarios' prints"
    duration = min(scenario.duration_s, 2.0)
    traj = scenario.simulate(duration=duration)
    assert isinstance(traj, Trajectory)
    n = int(round(duration * scenario.rate_hz)) + 1
    assert len(traj) == n
    np.testing.assert_allclose(np.diff(traj.t), 1 / scenario.rate_hz, rtol=1e-9)
    for name_, value in vars(traj).items():
        if isinstance(value, np.ndarray):
            assert np.all(np.isfinite(value)), name_
    np.testing.assert_allclose(np.linalg.norm(traj.q_wb, axis=1), 1.0, atol=1e-12)
    # The field in body axes is the world field turned by the attitude: R_bw m_w to round-off.
    m_w = traj.environment.magnetic_field_w
    expected = quat_rotate(quat_conjugate(traj.q_wb), m_w)
    np.testing.assert_allclose(traj.mag_b, expected, rtol=0, atol=16 * EPS * np.linalg.norm(m_w))
    # Kinematic consistency: ω_b with the differenced attitude, α_b with the differenced ω_b, v_w with the
    # differenced position, f_b = R_bw(p̈ + 2Ω×v − g) with its second differences, each to the central
    # differences' truncation bound (kinematics_checks), on an exact binary grid at least as fine as the
    # file's rate, not across the corners of the rate steps' ramps. Not the drop: its 1 ms contact shocks
    # span two samples (test_impact checks its free flight and contacts). Not a recorded motion: a cubic
    # spline's third derivative jumps at every knot, which the truncation bounds exclude (its derivatives
    # are the spline's own, held against scipy's in test_smoothing_spline and against the original
    # motion in test_recorded).
    if scenario.kind not in ("drop", "recorded"):
        t = uniform_times(0.0, duration, 2.0 ** np.floor(np.log2(1 / scenario.rate_hz)))
        corners = rate_step_corners(scenario.spec.steps) if getattr(scenario.spec, "steps", None) else []
        traj = scenario.spec.trajectory(t)
        # A 1000 times tighter solve of the integrated kinds measures their solver's error.
        tight = scenario.spec.model().trajectory(t, rtol=1e-13) if scenario.kind in INTEGRATED else None
        keep = np.ones(len(t) - 2, dtype=bool)
        for c in corners:
            keep &= ~((t[:-2] < c) & (c < t[2:]))
        assert_kinematics(traj, estimated_bounds(traj, keep, tight), breakpoints=corners, sharp=1e-2)
    # The fully resolved TOML reloads to the same spec.
    again = scenario_from_dict(tomllib.loads(scenario.to_toml()))
    assert again.spec == scenario.spec


def test_unknown_and_missing_kind_are_named():
    with pytest.raises(ConfigError, match="key 'kind': unknown kind 'spinning-plate'"):
        scenario_from_dict({"kind": "spinning-plate", "duration_s": 1, "rate_hz": 1}, name="x.toml")
    with pytest.raises(ConfigError, match="key 'kind': missing required key"):
        scenario_from_dict({"duration_s": 1, "rate_hz": 1}, name="x.toml")


@pytest.mark.parametrize(
    "change, key",
    [
        ({"rotation": {"terms": 100_000_000}}, "rotation.terms"),  # 14 GB, minutes, before a bound
        ({"translation": {"terms": 1001}}, "translation.terms"),
        ({"duration_s": 1e9}, "duration_s"),
        ({"rate_hz": 1e8}, "rate_hz"),
    ],
)
def test_keys_that_size_a_run_are_bounded_naming_the_key_and_why(change, key):
    """A count or span that would take gigabytes is refused when the file is read, with the reason."""
    data = tomllib.loads((config_dir() / "scenarios" / "smooth_manoeuvre.toml").read_text())
    for k, v in change.items():
        data[k] = {**data[k], **v} if isinstance(v, dict) else v
    with pytest.raises(ConfigError, match=rf"x.toml: key '{key}': .* is more than the limit of .*: \w+"):
        scenario_from_dict(data, name="x.toml")
    edge = tomllib.loads((config_dir() / "scenarios" / "smooth_manoeuvre.toml").read_text())
    edge["rotation"]["terms"] = 1000
    assert scenario_from_dict(edge, name="x.toml").spec.rotation.terms == 1000


@pytest.mark.parametrize("name", ["omega_b", "alpha_b", "specific_force_b", "pos_w", "vel_w", "mag_b"])
@pytest.mark.parametrize("shape", [(4, 4), (3, 3), (4,)])
def test_trajectory_refuses_a_vector_of_the_wrong_shape_naming_it(name, shape):
    """Every (N, 3) channel of a Trajectory is checked against N = len(t)."""
    n = 4
    arrays = {k: np.zeros((n, 3)) for k in ("omega_b", "alpha_b", "specific_force_b", "pos_w", "vel_w", "mag_b")}
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    assert len(Trajectory(t=np.arange(n, dtype=float), q_wb=q, **arrays)) == n
    arrays[name] = np.zeros(shape)
    with pytest.raises(ValueError, match=rf"^{name} must have shape \(4, 3\), got \({', '.join(map(str, shape))},?\)$"):
        Trajectory(t=np.arange(n, dtype=float), q_wb=q, **arrays)


@pytest.mark.parametrize("shape", [(4, 5), (5, 4), (4, 4, 1), (4, 3)])
def test_trajectory_refuses_an_attitude_of_the_wrong_shape(shape):
    n = 4
    arrays = {k: np.zeros((n, 3)) for k in ("omega_b", "alpha_b", "specific_force_b", "pos_w", "vel_w", "mag_b")}
    with pytest.raises(ValueError, match=r"^q_wb must have shape \(4, 4\)"):
        Trajectory(t=np.arange(n, dtype=float), q_wb=np.ones(shape), **arrays)


@pytest.mark.parametrize("index", [0, 2, 4, -1, -2, -5, np.int64(3)])
def test_trajectory_integer_index_gives_that_one_sample(index):
    n = 5
    arrays = {k: np.arange(3 * n, dtype=float).reshape(n, 3) for k in ("omega_b", "alpha_b", "pos_w", "vel_w")}
    arrays |= {k: np.zeros((n, 3)) for k in ("specific_force_b", "mag_b")}
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    traj = Trajectory(t=np.arange(n, dtype=float), q_wb=q, **arrays)
    one = traj[index]
    assert len(one) == 1
    assert one.t[0] == traj.t[index]
    assert np.array_equal(one.omega_b[0], traj.omega_b[index])

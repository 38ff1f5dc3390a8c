"""The rigid body [x, q, P, L] and the segmented DOP853 integrator: conservation, closed forms, lever
arms against finite differences, impulses at events.

Tolerances come from theory: DOP853 keeps each step's local error below ``rtol·|y| + atol``, so after
``n`` steps a conserved quantity has drifted by at most about ``n·rtol`` relative (twice that for a
quadratic one, like energy); finite differences err by their truncation terms ``h²/6 |p'''|`` and
``h²/12 |p''''|`` plus rounding ``ε|p|/h`` and ``ε|p|/h²``.
"""

import numpy as np
import pytest

from gyroemu.dynamics.gyrostat import Gyrostat
from gyroemu.dynamics.integrate import Jump, integrate
from gyroemu.dynamics.rigid_body import (
    L,
    P,
    Q,
    RigidBody,
    X,
    point_acceleration,
    point_position,
    point_velocity,
    rotate,
    rotate_back,
    rotation_matrix,
)
from gyroemu.dynamics.rotation import quat_from_euler_zyx, quat_to_matrix

EPS = np.finfo(float).eps
RTOL = 1e-10
INERTIA = np.diag([0.8, 1.5, 2.1])


def tumbling_body():
    """An asymmetric body spun near its intermediate axis: it flips over and over (a hard case)."""
    body = RigidBody(3.0, INERTIA)
    y0 = body.state((0.0, 0.0, 0.0), quat_from_euler_zyx([0.3, -0.2, 0.5]), (0.5, -1.0, 2.0), (0.05, 3.0, 0.08))
    return body, y0


def test_rotation_matrix_matches_scipy_for_single_and_stacked_quaternions():
    q = quat_from_euler_zyx(np.random.default_rng(1).uniform(-3, 3, size=(5, 3)))
    np.testing.assert_allclose(rotation_matrix(q), quat_to_matrix(q), atol=1e-15)
    np.testing.assert_allclose(rotation_matrix(q[2] * 3.0), quat_to_matrix(q[2]), atol=1e-15)  # normalised


def test_torque_free_body_conserves_energy_and_world_angular_momentum():
    body, y0 = tumbling_body()
    t = np.linspace(0.0, 500.0, 5001)
    sol = integrate(lambda tt, y: body.derivative(tt, y), t, y0, rtol=RTOL, atol=1e-13)
    energy = body.kinetic_energy(sol.y)
    drift = np.abs(energy / energy[0] - 1.0).max()
    assert drift <= 2.0 * sol.n_steps * RTOL, (drift, sol.n_steps)
    # L is a state with L̇ = 0: a Runge-Kutta step adds zero to it, so it is conserved exactly.
    assert np.array_equal(sol.y[:, L], np.broadcast_to(y0[L], sol.y[:, L].shape))
    # ... and the body's own angular momentum R I_b ω_b, from the sampled ω_b, is that L.
    _, omega_b, _ = body.accelerations(t, sol.y)
    r = rotation_matrix(sol.y[:, Q])
    l_from_omega = rotate(r, omega_b @ INERTIA.T)
    np.testing.assert_allclose(l_from_omega, sol.y[:, L], rtol=0, atol=20 * EPS * np.linalg.norm(y0[L]))
    assert np.abs(np.linalg.norm(sol.y[:, Q], axis=1) - 1.0).max() < 4 * EPS


def test_body_axes_gyrostat_form_conserves_world_angular_momentum_to_tolerance():
    """The gyrostat integrates I ω̇ = −ω × Iω in body axes; with no rotors its world L = R I ω is not a
    state, so its constancy tests the integration (here through the intermediate-axis flips)."""
    body, y0 = tumbling_body()
    gyro = Gyrostat(body.mass, INERTIA)
    g0 = gyro.state(y0[X], y0[Q], y0[P] / body.mass, body.omega_b(y0))
    t = np.linspace(0.0, 200.0, 2001)
    sol = integrate(lambda tt, y: gyro.derivative(tt, y), t, g0, rtol=RTOL, atol=1e-13)
    l_world = gyro.angular_momentum_w(t, sol.y)
    assert np.abs(l_world - y0[L]).max() <= sol.n_steps * RTOL * np.linalg.norm(y0[L])


@pytest.mark.parametrize("form", ["world momentum [x, q, P, L]", "body-axes Euler (gyrostat)"])
def test_symmetric_body_follows_the_closed_form_torque_free_precession(form):
    """Axisymmetric body, I1 = I2: ω3 is constant and (ω1, ω2) turns at λ = (I3 − I1)/I1 ω3
    (Euler: ω̇1 = −λ ω2, ω̇2 = λ ω1)."""
    inertia = np.diag([1.0, 1.0, 1.8])
    w0 = np.array([0.7, -0.2, 2.5])
    lam = (1.8 - 1.0) / 1.0 * w0[2]
    t = np.linspace(0.0, 300.0, 3001)
    if form.startswith("world"):
        body = RigidBody(1.0, inertia)
        sol = integrate(lambda tt, y: body.derivative(tt, y), t, body.state(omega_b=w0), rtol=RTOL, atol=1e-13)
        omega = body.accelerations(t, sol.y)[1]
    else:
        gyro = Gyrostat(1.0, inertia)
        sol = integrate(lambda tt, y: gyro.derivative(tt, y), t, gyro.state(omega_b=w0), rtol=RTOL, atol=1e-13)
        omega = sol.y[:, 10:13]
    c, s = np.cos(lam * t), np.sin(lam * t)
    expected = np.stack([w0[0] * c - w0[1] * s, w0[0] * s + w0[1] * c, np.full_like(t, w0[2])], axis=1)
    # Neutrally stable motion: the global error grows at most linearly, n steps of rtol each.
    assert np.abs(omega - expected).max() <= sol.n_steps * RTOL * np.linalg.norm(w0)


def test_constant_force_gives_the_closed_form_parabola():
    body = RigidBody(2.0, INERTIA)
    force = np.array([3.0, -1.0, -19.6])
    x0, v0 = np.array([1.0, 2.0, 10.0]), np.array([0.5, 0.0, 4.0])
    y0 = body.state(x0, (1, 0, 0, 0), v0, (0.3, -2.0, 1.0))
    t = np.linspace(0.0, 5.0, 501)
    f = lambda tt, y: body.derivative(tt, y, force=lambda _t, _y: force)
    sol = integrate(f, t, y0, rtol=RTOL, atol=1e-13)
    expected = x0 + v0 * t[:, None] + 0.5 * force / body.mass * t[:, None] ** 2  # x = x0 + v0 t + ½ F/m t²
    # DOP853 integrates this quadratic exactly; only rounding (and atol on steps) remains.
    np.testing.assert_allclose(sol.y[:, X], expected, rtol=0, atol=1e3 * EPS * np.abs(expected).max())
    np.testing.assert_allclose(sol.y_dot[:, P], np.broadcast_to(force, (t.size, 3)), rtol=0, atol=0)


def test_lever_arm_velocity_and_acceleration_match_finite_differences():
    body = RigidBody(1.5, INERTIA)
    force = lambda t, y: np.stack(np.broadcast_arrays(np.sin(t), 0.5 * np.cos(2 * t), -1.0), axis=-1)
    torque = lambda t, y: np.stack(np.broadcast_arrays(0.2 * np.cos(t), 0.1, -0.3 * np.sin(3 * t)), axis=-1)
    y0 = body.state((0, 0, 0), quat_from_euler_zyx([0.1, 0.2, 0.3]), (1.0, 0.0, 0.0), (1.0, -2.0, 1.5))
    lever_b = np.array([0.3, -0.2, 0.1])
    fine = 1e-3
    t = np.arange(0.0, 3.0 + fine / 2, fine)
    sol = integrate(lambda tt, y: body.derivative(tt, y, force, torque), t, y0, rtol=1e-12, atol=1e-14)
    acc, omega_b, alpha_b = body.accelerations(t, sol.y, force, torque)
    r = rotation_matrix(sol.y[:, Q])
    lever_w = rotate(r, lever_b)
    p = point_position(sol.y[:, X], r, lever_b)
    v = point_velocity(body.velocity(sol.y), rotate(r, omega_b), lever_w)
    a = point_acceleration(acc, rotate(r, omega_b), rotate(r, alpha_b), lever_w)
    for h_steps in (4, 2):
        h = h_steps * fine
        i = np.arange(h_steps, t.size - h_steps)
        v_fd = (p[i + h_steps] - p[i - h_steps]) / (2 * h)
        a_fd = (p[i + h_steps] - 2 * p[i] + p[i - h_steps]) / h**2
        # Bounds on p''' and p'''' from differencing the exact acceleration (1.5x for their own error).
        jerk = np.abs(np.diff(a, axis=0) / fine).max() * 1.5
        snap = np.abs(np.diff(a, 2, axis=0) / fine**2).max() * 1.5
        pmax = np.abs(p).max()
        assert np.abs(v_fd - v[i]).max() <= h**2 / 6 * jerk + 4 * EPS * pmax / h + 1e-10
        assert np.abs(a_fd - a[i]).max() <= h**2 / 12 * snap + 8 * EPS * pmax / h**2 + 1e-8
    # The same formula in body axes gives the same vector in body axes.
    a_b = point_acceleration(rotate_back(r, acc), omega_b, alpha_b, lever_b)
    np.testing.assert_allclose(a_b, rotate_back(r, a), atol=1e-13 * np.abs(a).max())


def test_impulse_changes_momenta_by_j_and_r_cross_j_at_the_event():
    body, y0 = tumbling_body()
    j = np.array([0.4, -1.2, 2.5])
    lever_w = np.array([0.1, 0.2, -0.3])
    after = body.apply_impulse(y0, j, y0[X] + lever_w)
    np.testing.assert_allclose(after[P] - y0[P], j, rtol=0, atol=4 * EPS * np.abs(after[P]).max())
    np.testing.assert_allclose(after[L] - y0[L], np.cross(lever_w, j), rtol=0, atol=4 * EPS * np.abs(after[L]).max())
    assert np.array_equal(after[:7], y0[:7])

    # Through the integrator: a jump scheduled at t = 0.35, between two samples and right on one.
    def kick(t, y):
        return body.apply_impulse(y, j, y[X] + rotate(rotation_matrix(y[Q]), (0.1, 0.0, 0.05)))

    for t_jump in (0.35, 0.4):
        t = np.linspace(0.0, 1.0, 11)
        sol = integrate(lambda tt, y: body.derivative(tt, y), t, y0, jumps=[Jump(t_jump, kick)])
        ((tj, before, after),) = sol.jumps
        assert tj == t_jump
        lever = rotate(rotation_matrix(before[Q]), (0.1, 0.0, 0.05))
        np.testing.assert_allclose(after[P] - before[P], j, atol=4 * EPS * np.abs(after[P]).max())
        np.testing.assert_allclose(after[L] - before[L], np.cross(lever, j), atol=4 * EPS * np.abs(after[L]).max())
        # Free motion on both sides: P and L constant, so samples show exactly the pre/post values.
        np.testing.assert_array_equal(sol.y[t < t_jump][:, P], np.broadcast_to(y0[P], (np.sum(t < t_jump), 3)))
        np.testing.assert_array_equal(sol.y[t >= t_jump][:, L], np.broadcast_to(after[L], (np.sum(t >= t_jump), 3)))


def test_integrate_rejects_bad_output_times():
    body, y0 = tumbling_body()
    with pytest.raises(ValueError, match="increasing"):
        integrate(lambda t, y: body.derivative(t, y), [0.0, 2.0, 1.0], y0)

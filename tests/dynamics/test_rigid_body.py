"""The rigid body [x, q, P, L] and the segmented DOP853 integrator: conservation, closed forms, lever
arms against finite differences, impulses at events.

Tolerances come from theory: DOP853 keeps each step's local error below ``rtol·|y| + atol``, so after
``n`` steps a conserved quantity has drifted by at most about ``n·rtol`` relative (twice that for a
quadratic one, like energy); finite differences err by their truncation terms ``h²/6 |p'''|`` and
``h²/12 |p''''|`` plus rounding ``ε|p|/h`` and ``ε|p|/h²``.
"""

import numpy as np
import pytest

from gyroemu.dynamics.body_kernels import rotate, rotate_back, rotation_matrix
from gyroemu.dynamics.earth import earth_rate_enu, normal_gravity
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
)
from gyroemu.dynamics.rotation import quat_from_euler_zyx, quat_multiply, quat_to_matrix

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


# --------------------------------------------------------------------------------------------
# A rotating world frame: Coriolis in the equations of motion and in the reported acceleration
# --------------------------------------------------------------------------------------------

OMEGA_FRAME = np.array([0.3, -0.5, 1.2])  # Ω, rad/s: a general direction, |Ω| = 1.33 rad/s (a turn in 4.7 s)


def rotate_about(axis_rate, t, v):
    """``Rot(−Ω t) v`` by Rodrigues' formula: ``v`` turned about Ω̂ by −|Ω| t, for times ``t`` (k,)."""
    w = np.linalg.norm(axis_rate)
    n = axis_rate / w
    c, s = np.cos(w * t)[:, None], np.sin(w * t)[:, None]
    v = np.broadcast_to(v, (t.size, 3))
    return v * c - np.cross(n, v) * s + n * (v @ n)[:, None] * (1 - c)


def centrifugal(body):
    """``F = −m Ω × (Ω × x)``: the only force a free particle feels in the turning world frame. The model
    keeps centrifugal in ``F`` (module docstring: "gravity and centrifugal are in F"), so a free particle
    is integrated with this force and no other."""
    omega = body.frame_rate_w
    return lambda t, y: -body.mass * np.cross(omega, np.cross(omega, y[..., X]))


@pytest.mark.parametrize("inertial_velocity", [(0.0, 0.0, 0.0), (0.7, -0.4, 0.25)], ids=["at rest", "uniform motion"])
def test_free_particle_seen_from_a_rotating_frame_follows_the_closed_form(inertial_velocity):
    """A body with no force and no torque, at ``r0 + u t`` in inertial space, not turning, seen from a
    world frame turning at Ω (the frames coincide at t = 0):

        r(t) = Rot(−Ω t) (r0 + u t)                                    position in the world frame
        v(t) = ṙ = Rot(−Ω t) u − Ω × r                                 world-relative velocity
        a(t) = r̈ = Ω × (Ω × r) − 2 Ω × Rot(−Ω t) u                     (= −2Ω×v − Ω×(Ω×r))
        q(t) = (cos ½|Ω|t, −Ω̂ sin ½|Ω|t) ⊗ q0                         attitude: it turns at −Ω

    At rest (u = 0) the position circles the axis Ω̂ at −Ω with the centripetal a = Ω × (Ω × r). ``a`` is
    what :meth:`RigidBody.accelerations` reports as ``acc_w`` (``Ṗ/m``, the world-relative acceleration,
    with ``F`` = the centrifugal force, as the model's ``F`` holds it).
    """
    body = RigidBody(2.0, INERTIA, frame_rate_w=OMEGA_FRAME)
    force = centrifugal(body)
    u = np.asarray(inertial_velocity)
    r0, q0 = np.array([1.0, -0.5, 0.8]), quat_from_euler_zyx([0.4, -0.3, 0.2])
    t = np.linspace(0.0, 20.0, 401)  # 4.2 turns of the frame
    w = np.linalg.norm(OMEGA_FRAME)

    r = rotate_about(OMEGA_FRAME, t, r0 + u * t[:, None])
    ru = rotate_about(OMEGA_FRAME, t, u)
    v = ru - np.cross(OMEGA_FRAME, r)
    a = np.cross(OMEGA_FRAME, np.cross(OMEGA_FRAME, r)) - 2.0 * np.cross(OMEGA_FRAME, ru)
    half = np.column_stack([np.cos(0.5 * w * t), -np.sin(0.5 * w * t)[:, None] * OMEGA_FRAME / w])
    q = quat_multiply(half, q0)

    # 1. The reported acceleration at the exact states: the same vectors rearranged, so only rounding
    # differs. Each term (centrifugal |Ω|²|r|, Coriolis 2|Ω||v|, and 2|Ω||u|) passes through at most two
    # nested cross products, × m and / m, and the state's own rounding of v: a few ε of its size each;
    # 32 ε of their sum covers it. (The wrong sign of 2Ω×P would be off by 4|Ω × v| ~ 1 m/s².)
    y_exact = body.state(r, q, v, (0.0, 0.0, 0.0))
    acc, omega_b, alpha_b = body.accelerations(t, y_exact, force)
    scale = w**2 * np.abs(r).max() + 2 * w * np.abs(v).max() + 2 * w * np.linalg.norm(u)
    np.testing.assert_allclose(acc, a, rtol=0, atol=32 * EPS * scale)
    np.testing.assert_array_equal(omega_b, 0.0)  # not turning in inertial space: L = 0 exactly
    np.testing.assert_array_equal(alpha_b, 0.0)
    if not u.any():  # at rest: the centripetal acceleration of the circle at −Ω, nothing else
        np.testing.assert_allclose(acc, np.cross(OMEGA_FRAME, np.cross(OMEGA_FRAME, r)), rtol=0, atol=32 * EPS * scale)

    # 2. Integrated from the state at t = 0 (DOP853, rtol 1e-10, atol 1e-13). Each step's local error is
    # kept below √13 (rtol |y_i| + atol) per component (scipy's RMS error norm over the 13 states):
    # ex in position, ev in velocity (P/m). Seen in inertial axes the error (δx, δv) of a step becomes
    # free motion, δX = δx, δV = δv + Ω × δx, so it grows to at most |δx|(1 + |Ω|T) + |δv| T in position
    # and |δv| + |Ω||δx| + |Ω|·(that) in velocity by the end. n steps add up.
    atol = 1e-13
    sol = integrate(lambda tt, y: body.derivative(tt, y, force), t, y_exact[0], rtol=RTOL, atol=atol)
    span = t[-1] - t[0]
    ex = np.sqrt(13) * (RTOL * np.abs(r).max() + atol)
    ev = np.sqrt(13) * (RTOL * np.abs(v).max() + atol / body.mass)
    pos_bound = sol.n_steps * (ex * (1 + w * span) + ev * span)
    vel_bound = sol.n_steps * (ev + w * ex) + w * pos_bound
    assert np.abs(sol.y[:, X] - r).max() <= pos_bound, (np.abs(sol.y[:, X] - r).max(), pos_bound)
    assert np.abs(body.velocity(sol.y) - v).max() <= vel_bound, (np.abs(body.velocity(sol.y) - v).max(), vel_bound)
    # q̇ = ½ (0, −Ω) ⊗ q is a rotation of q: errors do not grow; renormalising at most doubles them.
    q_bound = 2 * sol.n_steps * np.sqrt(13) * (RTOL + atol)
    assert np.abs(sol.y[:, Q] - q).max() <= q_bound, (np.abs(sol.y[:, Q] - q).max(), q_bound)
    np.testing.assert_array_equal(sol.y[:, L], 0.0)  # L̇ = −Ω × L = 0 from L = 0: exact
    # ... and the reported acceleration on the integrated states, a = −Ω×(Ω×x) − 2Ω×v: off by at most
    # |Ω|² δx + 2|Ω| δv from the state errors (rounding, 32 ε of the scale, is far below).
    acc_int = body.accelerations(t, sol.y, force)[0]
    acc_bound = w**2 * pos_bound + 2 * w * vel_bound + 32 * EPS * scale
    assert np.abs(acc_int - a).max() <= acc_bound, (np.abs(acc_int - a).max(), acc_bound)
    # It is the derivative's own Ṗ/m (the docstring's acc_w), at the same states.
    np.testing.assert_allclose(acc_int, sol.y_dot[:, P] / body.mass, rtol=0, atol=4 * EPS * scale)


def test_projectile_on_the_rotating_earth_is_deflected_as_the_first_order_closed_form():
    """A body thrown horizontally at 300 m/s at latitude φ = 45° (world frame: ENU, turning with the
    Earth at Ω = ω_E (0, cos φ, sin φ); ``F = m g`` with normal gravity, which holds the centrifugal
    term). ``ṙ̇ = g − 2 Ω × ṙ`` is solved by the series ``r = r0 + Σ_k (−2[Ω]×)^k (v0 t^{k+1}/(k+1)! +
    g t^{k+2}/(k+2)!)``, whose first order in Ω is the textbook

        r(t) = r0 + v0 t + ½ g t² − Ω × v0 t² − ⅓ Ω × g t³
        a(t) = g − 2 Ω × v0 − 2 Ω × g t

    with the horizontal deflection to the right of the motion ω_E sin φ |v0| t² (northern hemisphere,
    Foucault's sin φ), the Eötvös lift ω_E cos φ v_east t² and the eastward drift ⅓ ω_E cos φ g t³.
    The terms k ≥ 2 are bounded by, with x = 2|Ω| t,

        |r − r₁| ≤ (|v0| t/3 + |g| t²/12) (eˣ − 1 − x),      |a − a₁| ≤ 2|Ω||v0| (eˣ − 1) + |g| (eˣ − 1 − x)

    (each k ≥ 2 term is (2|Ω|t)^k/k! times |v0| t/(k+1) ≤ |v0| t/3 and |g| t²/((k+1)(k+2)) ≤ |g| t²/12;
    for a, k ≥ 2 gives 2|Ω||v0| (x^{k−1}/(k−1)!) and |g| x^k/k!). Here x ≤ 1.5·10⁻³: 1.2 mm and 7.5·10⁻⁵
    m/s² against a deflection of 1.5 m and a Coriolis acceleration of 0.044 m/s².
    """
    lat = np.radians(45.0)
    omega = earth_rate_enu(lat)
    g = np.array([0.0, 0.0, -normal_gravity(lat)])
    body = RigidBody(5.0, INERTIA, frame_rate_w=omega)
    force = lambda tt, y: np.broadcast_to(body.mass * g, y.shape[:-1] + (3,))  # noqa: E731
    r0, v0 = np.array([0.0, 0.0, 1000.0]), np.array([300.0, 0.0, 0.0])  # due east, 300 m/s
    t = np.linspace(0.0, 10.0, 101)
    y0 = body.state(r0, (1, 0, 0, 0), v0, omega)  # turning with the Earth
    sol = integrate(lambda tt, y: body.derivative(tt, y, force), t, y0, rtol=RTOL, atol=1e-13)

    tc = t[:, None]
    r1 = r0 + v0 * tc + 0.5 * g * tc**2 - np.cross(omega, v0) * tc**2 - np.cross(omega, g) * tc**3 / 3
    a1 = g - 2 * np.cross(omega, v0) - 2 * np.cross(omega, g) * tc
    w, vmag, gmag = np.linalg.norm(omega), np.linalg.norm(v0), np.linalg.norm(g)
    x = 2 * w * t
    r_rem = (vmag * t / 3 + gmag * t**2 / 12) * (np.expm1(x) - x)
    a_rem = 2 * w * vmag * np.expm1(x) + gmag * (np.expm1(x) - x)
    # Integration error (as in the free-particle test, Ω t ≪ 1): n steps of √13 rtol |y| in position and
    # velocity, the velocity's growing by T; below 10⁻⁴ m, 10⁻⁵ m/s, added to the truncation bounds.
    xmax, vmax = np.abs(r1).max(), vmag + gmag * t[-1]
    pos_int = sol.n_steps * np.sqrt(13) * (RTOL * xmax + 1e-13 + (RTOL * vmax + 1e-13) * t[-1])
    vel_int = sol.n_steps * np.sqrt(13) * (RTOL * vmax + 1e-13)
    err_r = np.linalg.norm(sol.y[:, X] - r1, axis=1)
    assert np.all(err_r <= r_rem + pos_int), (err_r.max(), (r_rem + pos_int)[-1])

    # The reported acceleration: at the integrated states, within the truncation, the state errors
    # (2|Ω| δv) and rounding (16 ε of |g| + 2|Ω||v|).
    acc = body.accelerations(t, sol.y, force)[0]
    err_a = np.linalg.norm(acc - a1, axis=1)
    a_bound = a_rem + 2 * w * vel_int + 16 * EPS * (gmag + 2 * w * vmax)
    assert np.all(err_a <= a_bound), (err_a.max(), a_bound[-1])

    # The classic reading: deflected to the right of the motion (south, for a body going east; the
    # eastward drift and the Eötvös lift are at right angles to it) by ω_E sin φ |v0| t² (1.5 m at 10 s).
    right = np.cross(v0 / vmag, (0.0, 0.0, 1.0))
    deflection = (sol.y[:, X] - r0) @ right
    np.testing.assert_array_less(np.abs(deflection - omega[2] * vmag * t**2), r_rem + pos_int + 1e-12)
    assert deflection[-1] > 1.4


def test_state_stores_the_attitude_normalised():
    """A quaternion handed in at any scale is stored as the unit quaternion of the same attitude."""
    body = RigidBody(3.0, INERTIA)
    q = quat_from_euler_zyx([0.3, -0.2, 0.5])
    for scale in (3.0, 0.25):
        y = body.state((0.0, 0.0, 0.0), scale * q, (0.0, 0.0, 0.0), (0.1, 0.2, 0.3))
        np.testing.assert_allclose(y[Q], q, rtol=0, atol=4 * EPS)

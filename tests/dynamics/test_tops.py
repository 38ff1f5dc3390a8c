"""Free rigid body and heavy top against closed forms, invariants and finite differences.

Every tolerance is derived from theory: round-off (``eps`` times the number of sub-steps), the
splitting integrator's error contract (``DEFAULT_TOL`` per radian of the fastest split rotation), or
the truncation error of the finite difference it is compared with (``h²/6 |f'''|`` for a central
first difference, ``h²/12 |f''''|`` for a second difference), the derivative bounded from the samples.

Run alone: ``python -m pytest tests/dynamics/test_tops.py -n 0`` (~15 s on one core, plus ~10 s the
first time, while numba compiles and caches the kernels).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
import tomli_w
from scipy.special import ellipj, ellipk

from gyroemu.dynamics import ConfigError, load_scenario, scenario_from_dict
from gyroemu.dynamics.config import config_dir, read_toml
from gyroemu.dynamics.rotation import (
    body_rate_from_euler_zxz,
    body_rate_from_quat_derivative,
    quat_angle,
    quat_conjugate,
    quat_exp,
    quat_from_euler_zxz,
    quat_from_matrix,
    quat_from_rotvec,
    quat_multiply,
    quat_rotate,
)
from gyroemu.dynamics.splitting import COMPOSITIONS, DEFAULT_TOL, integrate_heavy_top, plan_steps
from gyroemu.dynamics.tops import pivot_moments

EPS = np.finfo(float).eps
SCENARIOS = ("free_symmetric_top", "intermediate_axis_flip", "heavy_top")


def free_body(inertia, omega_b, q_wb=(1.0, 0.0, 0.0, 0.0)):
    """A free-rigid-body scenario from values (1 kHz)."""
    return scenario_from_dict(
        {
            "kind": "free-rigid-body",
            "duration_s": 1.0,
            "rate_hz": 1000.0,
            "body": {"inertia_kgm2": np.asarray(inertia).tolist()},
            "initial": {"omega_b": list(omega_b), "q_wb": list(q_wb)},
        }
    )


def world_momentum(traj, inertia_b):
    """``L_w = R I ω_b``, (N, 3)."""
    return quat_rotate(traj.q_wb, traj.omega_b @ np.asarray(inertia_b).T)


def central_difference(f, h):
    """``(f[k+1] − f[k−1]) / 2h`` at the interior samples."""
    return (f[2:] - f[:-2]) / (2.0 * h)


def max_derivative(f, h, order, *, norm=False):
    """``max |f⁽ⁿ⁾|`` over the samples and components (or of the vector norm), estimated by n-th
    differences (exact to O(h²))."""
    d = np.diff(f, n=order, axis=0)
    return (np.linalg.norm(d, axis=1) if norm else np.abs(d)).max() / h**order


# --------------------------------------------------------------------------------------------------
# Free symmetric top: the lecture's closed form


@pytest.mark.parametrize(
    "ixx, izz, a0, phase, omega_z",
    [(2.0, 3.0, 0.3, 0.4, 1.0), (3.0, 1.2, 0.5, -1.1, -0.8)],  # oblate; prolate, spinning backwards
    ids=["oblate", "prolate"],
)
def test_free_symmetric_top_matches_closed_form(ixx, izz, a0, phase, omega_z):
    inertia = np.diag([ixx, ixx, izz])
    q0 = quat_from_rotvec([0.3, -0.5, 0.2])
    omega0 = [a0 * np.sin(phase), -a0 * np.cos(phase), omega_z]
    traj = free_body(inertia, omega0, q0).simulate(duration=1000.0)
    t = traj.t

    # Lecture 11: ω_x = a0 sin(Ωt + φ), ω_y = −a0 cos(Ωt + φ), ω_z constant, Ω = (Izz − Ixx)/Ixx ω_z.
    big_omega = (izz - ixx) / ixx * omega_z
    expected = np.stack(
        [a0 * np.sin(big_omega * t + phase), -a0 * np.cos(big_omega * t + phase), np.full_like(t, omega_z)],
        axis=-1,
    )
    # A symmetric body's split flows commute: the scheme is exact, one step per sample; what is left
    # is round-off, one rounding per sub-flow (3) and renormalisation (1) per step, accumulating at
    # worst linearly: 1e6 steps · 4 eps · |ω| < 1e-9 rad/s.
    steps = len(t)
    assert np.abs(traj.omega_b - expected).max() < steps * 4 * EPS * np.linalg.norm(omega0) < 1e-9

    # The angular momentum is fixed in space.
    L_w = world_momentum(traj, inertia)
    assert np.abs(L_w - L_w[0]).max() < steps * 4 * EPS * np.linalg.norm(L_w[0])

    # Attitude: a turn about L_w at |L|/Ixx composed with the body spin −Ω about body z:
    # q(t) = exp(L_w t / 2Ixx) ⊗ q0 ⊗ exp(−Ω t e_z / 2).
    spin = np.zeros((len(t), 3))
    spin[:, 2] = -0.5 * big_omega * t
    q_closed = quat_multiply(quat_multiply(quat_exp(0.5 / ixx * t[:, None] * L_w[0]), q0), quat_exp(spin))
    total_angle = (np.linalg.norm(L_w[0]) / ixx + abs(big_omega)) * t[-1]
    assert quat_angle(traj.q_wb, q_closed).max() < steps * 4 * EPS + total_angle * 4 * EPS


def test_non_diagonal_tensor_is_integrated_in_principal_axes():
    # The same body described in axes b' turned by Q from its principal axes: I_b' = Q D Qᵀ.
    moments = np.array([2.0, 3.0, 4.0])
    q_turn = quat_from_rotvec([0.4, 0.1, -0.7])
    turn = quat_rotate(q_turn, np.eye(3)).T  # Q: columns are the principal axes in b'
    q0 = quat_from_rotvec([0.1, 0.2, 0.3])
    omega0_p = np.array([0.2, -0.3, 2.0])  # near the major axis: stable, no exponential growth
    principal = free_body(moments, omega0_p, q0).simulate(duration=10.0)
    turned = free_body(turn @ np.diag(moments) @ turn.T, turn @ omega0_p, quat_multiply(q0, quat_conjugate(q_turn)))
    turned = turned.simulate(duration=10.0)

    # ω_b' = Q ω_p, q_wb' = q_wp ⊗ q(Q)*: equal up to the eigen-decomposition's round-off (~10 eps),
    # carried along a motion of |ω| T ≈ 20 rad.
    bound = 10 * EPS * np.linalg.norm(omega0_p) * 20
    assert np.abs(turned.omega_b - principal.omega_b @ turn.T).max() < bound
    assert quat_angle(turned.q_wb, quat_multiply(principal.q_wb, quat_conjugate(q_turn))).max() < 10 * EPS * 20
    assert np.allclose(quat_from_matrix(turn), q_turn) or np.allclose(quat_from_matrix(turn), -q_turn)


# --------------------------------------------------------------------------------------------------
# Asymmetric free body: invariants and the intermediate-axis flips


def flip_period(moments, omega0):
    """Period of Euler's equations' Jacobi-elliptic solution, ``T = 4 K(m) / λ`` (Landau & Lifshitz,
    *Mechanics*, §37), with ``I1 < I2 < I3`` and ``2E = Σ I ω²``, ``L² = Σ (I ω)²``."""
    order = np.argsort(moments)
    i1, i2, i3 = np.asarray(moments, float)[order]
    w = np.asarray(omega0, float)[order]
    e2 = i1 * w[0] ** 2 + i2 * w[1] ** 2 + i3 * w[2] ** 2
    l2 = (i1 * w[0]) ** 2 + (i2 * w[1]) ** 2 + (i3 * w[2]) ** 2
    if l2 < e2 * i2:  # the motion circles the minor axis: swap the roles of I1 and I3
        i1, i3 = i3, i1
    lam = np.sqrt((i3 - i2) * (l2 - e2 * i1) / (i1 * i2 * i3))
    m = (i2 - i1) * (e2 * i3 - l2) / ((i3 - i2) * (l2 - e2 * i1))
    return 4.0 * ellipk(m) / lam


def upward_zero_crossings(t, f):
    """Times where ``f`` crosses zero upwards, linearly interpolated between samples."""
    k = np.nonzero((f[:-1] < 0) & (f[1:] >= 0))[0]
    return t[k] - f[k] * (t[k + 1] - t[k]) / (f[k + 1] - f[k])


def test_intermediate_axis_flips_conserve_energy_and_momentum_and_keep_their_period():
    scenario = load_scenario("intermediate_axis_flip")
    inertia = np.diag(scenario.spec.body.inertia_kgm2)
    traj = scenario.simulate(duration=1000.0)

    energy = 0.5 * np.einsum("ni,ij,nj->n", traj.omega_b, inertia, traj.omega_b)
    L_w = world_momentum(traj, inertia)
    assert np.abs(energy / energy[0] - 1).max() < 1e-9
    assert np.abs(L_w - L_w[0]).max() / np.linalg.norm(L_w[0]) < 1e-9

    # The rate about the intermediate axis (body y) is ω_2 ∝ sn(λt + τ0): one period per upward
    # zero crossing. Averaging over ~300 periods leaves the interpolation error (at an inflection
    # point of sn, O(h³)) far below 1e-6.
    crossings = upward_zero_crossings(traj.t, traj.omega_b[:, 1])
    measured = (crossings[-1] - crossings[0]) / (len(crossings) - 1)
    expected = flip_period(np.diag(inertia), scenario.spec.initial.omega_b)
    assert len(crossings) > 100
    assert abs(measured / expected - 1) < 1e-6


# --------------------------------------------------------------------------------------------------
# Heavy top: invariants, the turning points of the nutation, the elliptic solution


class Lagrange:
    """The Lagrange top's reduction to ``u = cos θ`` (Goldstein §5.7).

    ``u̇² = f(u) = (1 − u²)(α − β u) − (b − a u)²`` with ``a = L₃/A``, ``b = L_z/A``,
    ``α = 2 (E − L₃²/2C)/A``, ``β = 2 m g l / A``; ``u`` moves between the two roots ``u1 < u2``
    of ``f`` in ``[−1, 1]`` as ``u = u1 + (u2 − u1) sn²(λ t + τ0, m)``, ``m = (u2 − u1)/(u3 − u1)``,
    ``λ = ½ sqrt(β (u3 − u1))``.
    """

    def __init__(self, scenario):
        body, env = scenario.spec.body, scenario.spec.environment
        self.A, self.C = pivot_moments(body.mass_kg, body.inertia_kgm2, body.cm_height_m)
        self.mgl = body.mass_kg * env.gravity_m_s2 * body.cm_height_m
        self.moments = np.array([self.A, self.A, self.C])

    def invariants(self, traj):
        """Energy (J), ``L_z`` and ``L₃`` (kg m²/s) at each sample."""
        L_b = traj.omega_b * self.moments
        n_z = quat_rotate(traj.q_wb, np.array([0.0, 0.0, 1.0]))[:, 2]
        energy = 0.5 * np.sum(traj.omega_b * L_b, axis=1) + self.mgl * n_z
        return energy, quat_rotate(traj.q_wb, L_b)[:, 2], L_b[:, 2]

    def cubic(self, traj):
        energy, lz, l3 = (x[0] for x in self.invariants(traj))
        a, b = l3 / self.A, lz / self.A
        alpha, beta = 2.0 * (energy - l3**2 / (2.0 * self.C)) / self.A, 2.0 * self.mgl / self.A
        coefficients = [beta, -(alpha + a * a), 2.0 * a * b - beta, alpha - b * b]
        return np.polynomial.Polynomial(coefficients[::-1]), np.sort(np.roots(coefficients).real)


def cos_nutation(traj):
    return quat_rotate(traj.q_wb, np.array([0.0, 0.0, 1.0]))[:, 2]


@pytest.fixture(scope="module")
def heavy_top_100s():
    scenario = load_scenario("heavy_top")
    return scenario, scenario.simulate(duration=100.0)


def test_heavy_top_conserves_energy_vertical_momentum_and_spin(heavy_top_100s):
    scenario, traj = heavy_top_100s
    for invariant in Lagrange(scenario).invariants(traj):
        assert np.abs(invariant / invariant[0] - 1).max() < 1e-9


def test_heavy_top_nutates_between_the_roots_of_the_cubic(heavy_top_100s):
    scenario, traj = heavy_top_100s
    top = Lagrange(scenario)
    f, (u1, u2, u3) = top.cubic(traj)
    u = cos_nutation(traj)
    assert -1 < u1 < u2 < 1 < u3

    # The integrator's contract: error per radian of the fastest rotation (|L|/A ≤ ω_fast) is at most
    # DEFAULT_TOL, so over the run the state is off by at most DEFAULT_TOL ω_fast T (relative).
    omega_fast = np.linalg.norm(traj.omega_b * top.moments, axis=1).max() / top.A
    integration = DEFAULT_TOL * omega_fast * traj.duration
    assert u.min() > u1 - integration and u.max() < u2 + integration

    # It reaches both: near a turning point u ≈ u_i + ½ ü (t − t_i)², ü = f'(u_i)/2, and a sample
    # lies within h/2 of t_i.
    h = traj.t[1] - traj.t[0]
    reach = np.abs(f.deriv()(np.array([u1, u2]))).max() / 4 * (h / 2) ** 2 + integration
    assert u.min() < u1 + reach and u.max() > u2 - reach


def test_heavy_top_nutation_follows_the_elliptic_solution(heavy_top_100s):
    scenario, traj = heavy_top_100s
    top = Lagrange(scenario)
    _, (u1, u2, u3) = top.cubic(traj)
    m = (u2 - u1) / (u3 - u1)
    lam = 0.5 * np.sqrt(2.0 * top.mgl / top.A * (u3 - u1))
    # The scenario starts with θ̇ = 0 at the smaller tilt: u(0) = u2, sn² = 1, τ0 = K(m).
    assert scenario.spec.initial.euler_zxz_rates_rad_s[1] == 0.0
    sn = ellipj(lam * traj.t + ellipk(m), m)[0]
    expected = u1 + (u2 - u1) * sn**2

    omega_fast = np.linalg.norm(traj.omega_b * top.moments, axis=1).max() / top.A
    integration = DEFAULT_TOL * omega_fast * traj.duration
    # The reference's own error: the roots carry ~10 eps relative, a phase error of 10 eps λ T.
    reference = (u2 - u1) * 10 * EPS * lam * traj.duration * 2
    assert np.abs(cos_nutation(traj) - expected).max() < integration + reference


def test_heavy_top_attitude_follows_the_integrals_of_the_euler_angle_rates(heavy_top_100s):
    scenario, traj = heavy_top_100s
    top = Lagrange(scenario)
    energy, lz, l3 = (x[0] for x in top.invariants(traj))
    _, (u1, u2, u3) = top.cubic(traj)
    m = (u2 - u1) / (u3 - u1)
    lam = 0.5 * np.sqrt(2.0 * top.mgl / top.A * (u3 - u1))

    def cos_theta(t):
        return u1 + (u2 - u1) * ellipj(lam * t + ellipk(m), m)[0] ** 2

    # Goldstein §5.7: φ̇ = (b − a u)/(1 − u²), ψ̇ = L₃/C − φ̇ u, with a = L₃/A, b = L_z/A; integrated
    # over each sample interval by 8-point Gauss–Legendre (exact to (λ h)^16), summed in extended
    # precision.
    t, h = traj.t, traj.t[1] - traj.t[0]
    x, w = np.polynomial.legendre.leggauss(8)
    u = cos_theta(t[:-1, None] + 0.5 * h * (x + 1.0))
    phi_dot = (lz - l3 * u) / (top.A * (1.0 - u * u))  # (b − a u)/(1 − u²)
    phi = np.concatenate([[0.0], np.cumsum((0.5 * h * phi_dot @ w).astype(np.longdouble))])
    psi = l3 / top.C * t.astype(np.longdouble) - np.concatenate(
        [[0.0], np.cumsum((0.5 * h * (phi_dot * u) @ w).astype(np.longdouble))]
    )
    euler0 = np.asarray(scenario.spec.initial.euler_zxz_rad)
    expected = quat_from_euler_zxz(
        np.stack([euler0[0] + phi.astype(float), np.arccos(cos_theta(t)), euler0[2] + psi.astype(float)], axis=-1)
    )

    # Bound: the integrator's contract, DEFAULT_TOL per radian of the fastest rotation ω (the energy
    # bound of |L|/A, as the integrator takes it), plus one rounding (eps rad) per sub-flow rotation
    # of the attitude, plus the reference's rounding of angles up to |ψ| ~ 2·10⁴ rad.
    l_max = np.sqrt(2.0 * top.A * (energy - 0.5 * (1 / top.C - 1 / top.A) * l3**2 + top.mgl))
    omega = max(l_max / top.A, np.sqrt(top.mgl / top.A))
    composition, n_steps = plan_steps(t, omega, DEFAULT_TOL)
    rotations = composition.stages * n_steps.sum()
    bound = DEFAULT_TOL * omega * traj.duration + EPS * rotations + 4 * EPS * float(np.abs(psi).max())
    assert quat_angle(traj.q_wb, expected).max() < bound


@pytest.mark.parametrize("composition", COMPOSITIONS, ids=lambda c: c.name)
def test_compositions_reach_their_order(composition):
    scenario = load_scenario("heavy_top")
    top = Lagrange(scenario)
    first = scenario.simulate(duration=0.01)
    q0, L0_w = first.q_wb[0], quat_rotate(first.q_wb[0], first.omega_b[0] * top.moments)

    def state_at_half_second(samples):
        # A loose tol gives one step per sample: the step is 0.5 s / samples.
        t = np.linspace(0.0, 0.5, samples + 1)[1:]
        q, L = integrate_heavy_top(t, q0, L0_w, top.A, top.C, top.mgl, tol=1e3, compositions=[composition])
        return np.concatenate([q[-1], L[-1] / np.linalg.norm(L0_w)])

    # Order p: halving the step divides the error by 2^p (steps of 0.5 and 0.25 rad of the
    # nutation, in the asymptotic range of every method, above round-off even at order 8).
    reference = state_at_half_second(4096)
    e32, e64 = (np.abs(state_at_half_second(n) - reference).max() for n in (32, 64))
    assert abs(np.log2(e32 / e64) - composition.order) < 0.25


# --------------------------------------------------------------------------------------------------
# Consistency of the sampled truth


@pytest.mark.parametrize("name", SCENARIOS)
def test_alpha_and_omega_agree_with_finite_differences(name):
    traj = load_scenario(name).simulate(duration=2.0)
    h = traj.t[1] - traj.t[0]

    # α_b against the central difference of ω_b: truncation h²/6 |ω'''|, rounding eps |ω| / h.
    fd = central_difference(traj.omega_b, h)
    bound = h**2 / 6 * max_derivative(traj.omega_b, h, 3) * 1.1 + 2 * EPS * np.abs(traj.omega_b).max() / h
    assert np.abs(traj.alpha_b[1:-1] - fd).max() < bound

    # ω_b against 2 (q* ⊗ q̇)_vec with q̇ by central differences: |δω| ≤ 2 |δq̇| (4-vector norms).
    q_dot = central_difference(traj.q_wb, h)
    omega_fd = body_rate_from_quat_derivative(traj.q_wb[1:-1], q_dot)
    bound = 2 * (h**2 / 6 * max_derivative(traj.q_wb, h, 3, norm=True) * 1.1 + 2 * EPS / h)
    assert np.abs(traj.omega_b[1:-1] - omega_fd).max() < bound


def test_heavy_top_specific_force_is_the_centre_of_mass_acceleration():
    scenario = load_scenario("heavy_top")
    traj = scenario.simulate(duration=2.0)
    h = traj.t[1] - traj.t[0]
    g_w = np.array([0.0, 0.0, -scenario.spec.environment.gravity_m_s2])

    # pos_w is the centre of mass: l along the symmetry axis from the pivot at the origin.
    assert np.allclose(np.linalg.norm(traj.pos_w, axis=1), scenario.spec.body.cm_height_m, rtol=0, atol=1e-15)
    assert np.abs(traj.vel_w[1:-1] - central_difference(traj.pos_w, h)).max() < (
        h**2 / 6 * max_derivative(traj.pos_w, h, 3) * 1.1 + 2 * EPS * 0.03 / h
    )
    # f_b = R_bw (a_w − g_w), a_w by the second difference: truncation h²/12 |p''''|, rounding 4 eps |p| / h².
    acc_fd = (traj.pos_w[2:] - 2 * traj.pos_w[1:-1] + traj.pos_w[:-2]) / h**2
    f_fd = quat_rotate(quat_conjugate(traj.q_wb[1:-1]), acc_fd - g_w)
    bound = h**2 / 12 * max_derivative(traj.pos_w, h, 4) * 1.1 + 4 * EPS * 0.03 / h**2
    assert np.abs(traj.specific_force_b[1:-1] - f_fd).max() < bound


# --------------------------------------------------------------------------------------------------
# Config files


@pytest.mark.parametrize("name", SCENARIOS)
def test_each_config_loads_and_simulates(name):
    scenario = load_scenario(name)
    assert scenario.description and "\n" not in scenario.description
    traj = scenario.simulate(duration=0.5)
    assert len(traj) == 501
    for array in (traj.q_wb, traj.omega_b, traj.alpha_b, traj.specific_force_b, traj.pos_w, traj.vel_w):
        assert np.all(np.isfinite(array))
    assert np.abs(np.linalg.norm(traj.q_wb, axis=1) - 1).max() < 4 * EPS
    assert np.allclose(traj.omega_b[0], _initial_rate(scenario), rtol=1e-14, atol=1e-14)


def _initial_rate(scenario):
    initial = scenario.spec.initial
    if scenario.kind == "heavy-top":
        return body_rate_from_euler_zxz(np.asarray(initial.euler_zxz_rad), np.asarray(initial.euler_zxz_rates_rad_s))
    return np.asarray(initial.omega_b)


def _edited(name, section, key, value):
    data = read_toml(config_dir() / "scenarios" / f"{name}.toml")
    if value is None:
        data[section].pop(key)
    else:
        data[section][key] = value
    return data


@pytest.mark.parametrize(
    "name, section, key, value, words",
    [
        ("heavy_top", "body", "inertia_kgm2", [1.6e-5, 1.7e-5, 3.1e-5], "Ixx must equal Iyy"),
        ("heavy_top", "body", "inertia_kgm2", [1.0, 1.0, 3.0], "triangle inequality"),
        ("heavy_top", "body", "mass_kg", -0.1, "greater than 0"),
        ("free_symmetric_top", "body", "inertia_kgm2", [1.0, -1.0, 1.0], "positive definite"),
        ("free_symmetric_top", "body", "inertia_kgm2", [1.0, 2.0], "3 principal moments"),
        ("free_symmetric_top", "body", "inertia_kgm2", [[1, 0.1, 0], [0, 1, 0], [0, 0, 1]], "not symmetric"),
        ("free_symmetric_top", "initial", "q_wb", [1.0, 0.0, 0.0, 0.01], "unit quaternion"),
        ("free_symmetric_top", "initial", "omega_b", None, "missing"),
    ],
)
def test_config_errors_name_the_file_and_key(tmp_path, name, section, key, value, words):
    path = tmp_path / f"{name}.toml"
    path.write_text(tomli_w.dumps(_edited(name, section, key, value)))
    with pytest.raises(ConfigError) as err:
        load_scenario(path)
    assert err.value.key == f"{section}.{key}"
    assert str(path) in str(err.value) and words in str(err.value)


def test_nearly_unit_quaternion_is_normalised():
    data = _edited("free_symmetric_top", "initial", "q_wb", [0.6, 0.0, 0.8, 1e-7])
    q = np.asarray(scenario_from_dict(data).spec.initial.q_wb)
    assert abs(np.linalg.norm(q) - 1) <= 2 * EPS  # a couple of roundings


@pytest.mark.parametrize(
    "name, section, key, value, words",
    [
        # 1e200 overflowed |L|² (OverflowError); 1e12 rad/s asked the integrator for 1e13 steps a second.
        ("heavy_top", "initial", "euler_zxz_rates_rad_s", [0.0, 0.0, 1e200], "more than the limit of 100000"),
        ("heavy_top", "initial", "euler_zxz_rates_rad_s", [0.0, 0.0, 1e12], "more than the limit of 100000"),
        ("heavy_top", "initial", "euler_zxz_rates_rad_s", [-1e12, 0.0, 0.0], "more than the limit of 100000"),
        ("heavy_top", "body", "mass_kg", 1e300, "more than the limit of 1e+06"),
        ("heavy_top", "body", "cm_height_m", 1e300, "more than the limit of ±100"),
        ("heavy_top", "body", "cm_height_m", -1e300, "more than the limit of ±100"),
        ("heavy_top", "body", "inertia_kgm2", [1e300, 1e300, 1e300], "more than the limit of 1e+40"),
        ("heavy_top", "body", "inertia_kgm2", [1e-300, 1e-300, 1e-300], "less than the limit of 1e-20"),
        ("heavy_top", "environment", "gravity_m_s2", 1e300, "more than the limit of 10000"),
        ("free_symmetric_top", "initial", "omega_b", [1e200, 0.0, 0.0], "more than the limit of 100000"),
        ("intermediate_axis_flip", "initial", "omega_b", [0.02, 1e12, 0.02], "more than the limit of 100000"),
        ("intermediate_axis_flip", "body", "inertia_kgm2", [1e300, 2e300, 2.5e300], "more than the limit of 1e+40"),
        ("free_symmetric_top", "body", "inertia_kgm2", [1e-300, 1e-300, 1e-300], "less than the limit of 1e-20"),
        # An angle of 1e300 rad was taken: its sine and cosine hold no digit (float64 steps past a turn there).
        ("heavy_top", "initial", "euler_zxz_rad", [0.0, 1e300, 0.0], "more than 4 turns"),
        ("heavy_top", "initial", "euler_zxz_rad", [-1e300, 0.349066, 0.0], "more than 4 turns"),
        ("heavy_top", "initial", "euler_zxz_rad", [0.0, 0.349066, 26.0], "more than 4 turns"),
    ],
)
def test_absurd_rates_and_bodies_are_refused_naming_the_key(tmp_path, name, section, key, value, words):
    """Values whose squares leave float64 (an OverflowError mid-run, or NaN and a body standing still) or whose
    rates ask the integrator for days of work (a kernel no signal interrupts) are refused when the file is read."""
    path = tmp_path / f"{name}.toml"
    path.write_text(tomli_w.dumps(_edited(name, section, key, value)))
    with pytest.raises(ConfigError, match=re.escape(words)) as err:
        load_scenario(path)
    # a per-element bound (the angles) names the element: initial.euler_zxz_rad[1]
    assert re.fullmatch(rf"{section}\.{key}(\[\d\])?", err.value.key) and err.value.file == str(path)


@pytest.mark.parametrize(
    "name, edits, key",
    [
        # A slightly asymmetric rod spun about a long axis: its spin about the thin axis follows at (ΔI/I_min) ω.
        (
            "intermediate_axis_flip",
            {("body", "inertia_kgm2"): [1e-6, 1.0, 1.000001], ("initial", "omega_b"): [0.0, 100.0, 0.01]},
            "initial.omega_b",
        ),
        # A 1000 t top of 1e-13 m radius of gyration and cm height under 1000 g: a pendulum frequency of 2e8 rad/s.
        (
            "heavy_top",
            {
                ("body", "inertia_kgm2"): [1e-20, 1e-20, 1e-20],
                ("body", "cm_height_m"): 1e-13,
                ("body", "mass_kg"): 1e6,
                ("environment", "gravity_m_s2"): 1e4,
            },
            "body.inertia_kgm2",
        ),
    ],
)
def test_a_body_the_integrator_cannot_follow_is_refused_naming_the_key(name, edits, key):
    """Rates within their limit can still make the split rotations absurdly fast with an extreme body:
    refused (MAX_SPLIT_FREQUENCY_RAD_S), not a run of hours."""
    from gyroemu.dynamics.tops import MAX_SPLIT_FREQUENCY_RAD_S

    data = read_toml(config_dir() / "scenarios" / f"{name}.toml")
    for (section, k), value in edits.items():
        data[section][k] = value
    with pytest.raises(ConfigError, match=re.escape(f"more than the limit of {MAX_SPLIT_FREQUENCY_RAD_S:g}")) as err:
        scenario_from_dict(data, name=name)
    assert err.value.key == key


def test_the_rate_limits_leave_the_shipped_tops_far_inside():
    """The shipped tops' split frequencies are a thousandth of the limit or less (their outputs unchanged)."""
    from gyroemu.dynamics.splitting import free_body_frequency, heavy_top_frequency
    from gyroemu.dynamics.tops import MAX_SPLIT_FREQUENCY_RAD_S, pivot_moments

    for name in ("heavy_top", "free_symmetric_top", "intermediate_axis_flip"):
        spec = load_scenario(name).spec
        if spec.kind == "heavy-top":
            a, c = pivot_moments(spec.body.mass_kg, spec.body.inertia_kgm2, spec.body.cm_height_m)
            mgl = spec.body.mass_kg * spec.environment.gravity_m_s2 * spec.body.cm_height_m
            euler, rates = np.asarray(spec.initial.euler_zxz_rad), np.asarray(spec.initial.euler_zxz_rates_rad_s)
            q0 = quat_from_euler_zxz(euler)
            L0 = quat_rotate(q0, np.array([a, a, c]) * body_rate_from_euler_zxz(euler, rates))
            omega = heavy_top_frequency(quat_rotate(q0, np.array([0.0, 0.0, 1.0])), L0, a, c, mgl)
        else:
            inertia = spec.body.tensor()
            omega = free_body_frequency(inertia @ np.asarray(spec.initial.omega_b), inertia)
        assert omega < MAX_SPLIT_FREQUENCY_RAD_S / 1000, name


@pytest.mark.parametrize(
    "name, section, key, value, named",
    [
        ("bench_static", "attitude", "rpy_deg", [0.0, 1e300, 0.0], "attitude.rpy_deg[1]"),
        ("rate_table_constant", "table", "base_rpy_deg", [0.0, 0.0, 1441.0], "table.base_rpy_deg[2]"),
        ("ship_waves", "ship", "heading_deg", -1e9, "ship.heading_deg"),
    ],
)
def test_orientation_angles_in_degrees_are_bounded_as_those_in_radians(name, section, key, value, named):
    """An orientation angle in degrees beyond 4 turns (1440°) is refused naming its key (1e300° was taken:
    no digit of its sine is left); 1440° itself is taken."""
    with pytest.raises(ConfigError) as err:
        scenario_from_dict(_edited(name, section, key, value))
    assert err.value.key == named, err.value
    edge = [0.0, 0.0, 1440.0] if isinstance(value, list) else -1440.0
    scenario_from_dict(_edited(name, section, key, edge))


def test_euler_angles_within_four_turns_are_taken_and_beyond_refused():
    """The bound is 4 turns either way (MAX_ANGLE_TURNS): a spin phase of 3.9 turns and a precession of −4
    turns are taken, the same top as at their remainders modulo 2π (to the rounding of the angle)."""
    from gyroemu.dynamics.config import MAX_ANGLE_TURNS

    limit = MAX_ANGLE_TURNS * 2 * np.pi
    assert MAX_ANGLE_TURNS == 4
    near = scenario_from_dict(_edited("heavy_top", "initial", "euler_zxz_rad", [-limit, 0.349066, 3.9 * 2 * np.pi]))
    assert near.spec.initial.euler_zxz_rad[0] == -limit
    with pytest.raises(ConfigError) as err:
        scenario_from_dict(_edited("heavy_top", "initial", "euler_zxz_rad", [0.0, 0.349066, limit * (1 + 1e-12)]))
    assert err.value.key == "initial.euler_zxz_rad[2]", err.value

"""The gyrostat: total angular momentum conserved while rotors spin up and gimbals turn, the closed-form
counter-rotation of a body whose rotor spins up, exact α from the equations.

Tolerances: DOP853's local error per step is below ``rtol·|y| + atol``; the world angular momentum
``R (I ω + h)`` is not a state here (``ω`` is), so over ``n`` steps it drifts by at most about
``n·rtol·|H|``.
"""

import numpy as np
import pytest

from gyroemu.dynamics.gyrostat import GimballedRotor, Gyrostat, Rotor, SpinProfile, W
from gyroemu.dynamics.integrate import Jump, integrate
from gyroemu.dynamics.rotation import quat_from_euler_zyx

RTOL = 1e-10
EPS = np.finfo(float).eps


def busy_gyrostat():
    """A tumbling body with a rotor spinning up and two CMGs whose gimbals swing."""
    rotor = Rotor((1.0, 0.0, 0.0), 0.02, SpinProfile(0.0, 300.0, t_start=2.0, duration=5.0))
    cmg1 = GimballedRotor((0.0, 0.0, 1.0), (1.0, 0.0, 0.0), 0.01, SpinProfile(400.0))
    cmg2 = GimballedRotor((1.0, 1.0, 0.0), (0.0, 0.0, 1.0), 0.015, SpinProfile(200.0, 500.0, 1.0, 3.0))
    return Gyrostat(20.0, np.diag([2.0, 3.0, 4.5]), rotors=[rotor], gimbals=[cmg1, cmg2])


def swing(t, y):
    """Commanded gimbal rates: smooth and different for each gimbal, rad/s."""
    t = np.asarray(t, dtype=float)
    return np.stack([0.8 * np.sin(1.3 * t), 0.5 * np.cos(0.7 * t) - 0.2], axis=-1)


def test_total_angular_momentum_is_conserved_while_rotors_spin_up_and_gimbals_turn():
    g = busy_gyrostat()
    y0 = g.state((0, 0, 0), quat_from_euler_zyx([0.2, 0.4, -0.3]), (0, 0, 0), (0.3, -0.5, 0.8), (0.1, -0.4))
    t = np.linspace(0.0, 60.0, 3001)
    f = lambda tt, y: g.derivative(tt, y, gimbal_rate=swing)
    sol = integrate(f, t, y0, jumps=[Jump(b) for b in g.breakpoints], rtol=RTOL, atol=1e-13)
    h_world = g.angular_momentum_w(t, sol.y)
    h0 = np.linalg.norm(h_world[0])
    drift = np.abs(h_world - h_world[0]).max()
    assert drift <= sol.n_steps * RTOL * h0, (drift, sol.n_steps)
    # The exchange is real: the rotors' momentum changed by far more than the drift.
    h_rotors = g.rotor_momentum_b(t, sol.y)
    assert np.ptp(h_rotors, axis=0).max() > 1e6 * drift
    # Gimbal angles integrate the commanded rates.
    expected = y0[13:] + np.stack([0.8 / 1.3 * (1 - np.cos(1.3 * t)), 0.5 / 0.7 * np.sin(0.7 * t) - 0.2 * t], axis=1)
    np.testing.assert_allclose(sol.y[:, 13:], expected, atol=sol.n_steps * RTOL * 10)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_spin_up_on_a_free_body_gives_the_closed_form_counter_rotation(axis):
    """A rotor spun up about a principal axis of a body at rest: H = I ω + J Ω = 0 throughout, so the
    body turns at ω = −J Ω(t) / I about that axis, at every instant of the spin-up, nothing else."""
    inertia = np.array([2.0, 3.0, 4.5])
    a = np.eye(3)[axis]
    spin = SpinProfile(0.0, 500.0, t_start=1.0, duration=4.0)
    g = Gyrostat(5.0, np.diag(inertia), rotors=[Rotor(a, 0.01, spin)])
    t = np.linspace(0.0, 8.0, 801)
    sol = integrate(
        lambda tt, y: g.derivative(tt, y), t, g.state(), jumps=[Jump(b) for b in g.breakpoints], rtol=RTOL, atol=1e-14
    )
    expected = np.outer(-0.01 * spin.rate(t) / inertia[axis], a)  # −ΔH / I
    np.testing.assert_allclose(sol.y[:, W], expected, rtol=0, atol=sol.n_steps * RTOL * 0.01 * 500 / inertia[axis])
    # Final rate: −J ΔΩ / I.
    np.testing.assert_allclose(sol.y[-1, W] @ a, -0.01 * 500.0 / inertia[axis], rtol=1e-9)


def test_alpha_is_the_exact_derivative_of_omega():
    """α from the equation of motion agrees with central differences of ω to the truncation bound
    h²/6 |ω'''| (ω''' bounded by differencing α twice, with 1.5x for that estimate's own error)."""
    g = busy_gyrostat()
    y0 = g.state(omega_b=(0.3, -0.5, 0.8), gimbal_angles=(0.1, -0.4))
    fine = 1e-3
    t = np.arange(0.0, 4.0 + fine / 2, fine)
    f = lambda tt, y: g.derivative(tt, y, gimbal_rate=swing)
    sol = integrate(f, t, y0, jumps=[Jump(b) for b in g.breakpoints], rtol=1e-12, atol=1e-14)
    omega, alpha = sol.y[:, W], sol.y_dot[:, W]
    h = 4 * fine
    i = np.arange(4, t.size - 4)
    alpha_fd = (omega[i + 4] - omega[i - 4]) / (2 * h)
    third = np.abs(np.diff(alpha, 2, axis=0)).max() / fine**2 * 1.5
    assert np.abs(alpha_fd - alpha[i]).max() <= h**2 / 6 * third + 4 * EPS * np.abs(omega).max() / h + 1e-10


def test_gimbal_geometry_and_jacobian():
    cmg = GimballedRotor((0.0, 0.0, 2.0), (3.0, 0.0, 0.0), 0.5, SpinProfile(10.0))
    np.testing.assert_allclose(cmg.spin_axis(np.pi / 2), [0.0, 1.0, 0.0], atol=1e-15)  # ŝ(90°) = ĝ × ŝ₀
    np.testing.assert_allclose(cmg.torque_axis(0.0), [0.0, 1.0, 0.0], atol=1e-15)
    g = Gyrostat(1.0, np.eye(3), gimbals=[cmg, GimballedRotor((1, 0, 0), (0, 1, 0), 0.2, SpinProfile(-7.0))])
    delta = np.array([0.3, -1.1])
    y = g.state(gimbal_angles=delta)
    step = 1e-6
    jac_fd = np.stack(
        [
            (
                g.rotor_momentum_b(0.0, g.state(gimbal_angles=delta + step * e))
                - g.rotor_momentum_b(0.0, g.state(gimbal_angles=delta - step * e))
            )
            / (2 * step)
            for e in np.eye(2)
        ],
        axis=1,
    )
    np.testing.assert_allclose(g.gimbal_jacobian(0.0, delta), jac_fd, atol=1e-8)
    with pytest.raises(ValueError, match="perpendicular"):
        GimballedRotor((0, 0, 1), (0, 1, 1), 1.0, SpinProfile(1.0))
    assert y.size == g.size == 15

"""Vehicles (gyroemu.dynamics.vehicles): the random manoeuvre and the car against finite differences and theory.

The finite-difference tolerances need bounds on third and fourth derivatives of compositions (the
attitude from Euler angles, roll ∝ κ(s(t)) v(t)², the position through a turn). They come from Cauchy's
method of majorants (:class:`Majorant`): if ``|f⁽ⁿ⁾| ≤ n! F_n`` and ``|g⁽ⁿ⁾| ≤ n! G_n`` for all n,
the power series with coefficients ``F_n`` majorises ``f``, and sums, products and compositions of majorants
majorise sums, products and compositions (Faà di Bruno's formula has non-negative coefficients);
``sin`` and ``cos`` of an angle with majorant ``e0 + Δ`` are majorised by ``exp(Δ)``. The primitive
bounds are the motion's amplitudes and frequencies.
"""

from __future__ import annotations

import warnings
from math import factorial

import numpy as np
import pytest
from kinematics_checks import EPS, DerivativeBounds, assert_kinematics, step_bound, uniform_times
from scipy.integrate import IntegrationWarning, quad

from gyroemu.dynamics import EARTH_RATE, ConfigError, scenario_from_dict
from gyroemu.dynamics.motion_kernels import smooth_step
from gyroemu.dynamics.rotation import body_rate_from_euler_zyx, euler_zyx_from_quat, quat_from_euler_zyx
from gyroemu.dynamics.vehicles import Road, SuspensionTransient, Turn, euler_zyx_motion

SITE = {"latitude_deg": -33.9, "height_m": 20.0}


class Majorant:
    """A truncated majorant series ``Σ c_n τⁿ``: ``|f⁽ⁿ⁾| ≤ n! c_n`` for ``n ≤ ORDER``."""

    ORDER = 6
    __array_ufunc__ = None  # numpy scalars defer to Majorant's operators

    def __init__(self, coefficients):
        c = np.zeros(self.ORDER + 1)
        c[: min(len(coefficients), self.ORDER + 1)] = coefficients[: self.ORDER + 1]
        self.c = c

    @classmethod
    def of_derivatives(cls, bounds):
        """From bounds on ``|f|, |f′|, |f″|, …``."""
        return cls([b / factorial(n) for n, b in enumerate(bounds)])

    def __add__(self, other):
        return Majorant(self.c + (other.c if isinstance(other, Majorant) else np.r_[other, np.zeros(self.ORDER)]))

    __radd__ = __add__

    def __mul__(self, other):
        if not isinstance(other, Majorant):
            return Majorant(self.c * abs(other))
        return Majorant(np.convolve(self.c, other.c)[: self.ORDER + 1])

    __rmul__ = __mul__

    def variation(self):
        """The series without its constant term: majorises ``f(t0 + τ) − f(t0)``."""
        return Majorant(np.r_[0.0, self.c[1:]])

    def derivative(self):
        return Majorant(self.c[1:] * np.arange(1, self.ORDER + 1))

    def integral(self):
        """Majorises ``∫₀^τ f``."""
        return Majorant(np.r_[0.0, self.c[:-1] / np.arange(1, self.ORDER + 1)])

    def compose(self, inner):
        """``Σ c_n innerⁿ`` for an ``inner`` without constant term: majorises ``f(x0 + δ(τ))``."""
        out, power = Majorant([self.c[0]]), Majorant([1.0])
        for n in range(1, self.ORDER + 1):
            power = power * inner
            out = out + self.c[n] * power
        return out

    def trig(self):
        """Majorises ``sin`` and ``cos`` of an angle with this majorant: ``exp`` of the variation."""
        return Majorant([1.0 / factorial(n) for n in range(self.ORDER + 1)]).compose(self.variation())

    def bound(self, n: int) -> float:
        """Bound on the n-th derivative."""
        return factorial(n) * self.c[n]


def euler_motion_bounds(roll, pitch, yaw, position_xy=None, position_z=None) -> DerivativeBounds:
    """Derivative bounds of the motion whose Euler angles have the given majorants.

    A quaternion component is a sum of two products of three half-angle sines and cosines:
    ``≪ 2 exp(½ (Δφ + Δθ + Δψ))`` (norm of 4 components: twice that). A component of ω_b is a sum of
    angle rates times products of sines and cosines: ``≪ (φ̇ + θ̇ + ψ̇) exp(Δφ + Δθ + Δψ)``; of the
    Earth term ``R_bw Ω``: ``≪ 6 Ω exp(Δφ + Δθ + Δψ)``.
    """
    variation = roll.variation() + pitch.variation() + yaw.variation()
    q_component = 2 * (0.5 * variation).trig()
    omega = (
        roll.derivative() + pitch.derivative() + yaw.derivative()
    ) * variation.trig() + 6 * EARTH_RATE * variation.trig()
    p3 = p4 = 0.0
    if position_xy is not None:
        p3 += np.sqrt(2) * position_xy.bound(3) + position_z.bound(3)
        p4 += np.sqrt(2) * position_xy.bound(4) + position_z.bound(4)
    return DerivativeBounds(q3=2 * q_component.bound(3), w3=np.sqrt(3) * omega.bound(3), p3=p3, p4=p4)


# --------------------------------------------------------------------------------------------------
# Euler kernel
# --------------------------------------------------------------------------------------------------


def test_euler_kernel_matches_rotation_module():
    rng = np.random.default_rng(1)
    rpy, rates, accels = rng.uniform(-3, 3, (3, 1000, 3))
    q, omega, alpha = euler_zyx_motion(rpy.T, rates.T, accels.T)
    q_ref = quat_from_euler_zyx(rpy)
    np.testing.assert_allclose(q * np.sign(np.sum(q * q_ref, axis=1))[:, None], q_ref, rtol=0, atol=4 * EPS)
    omega_ref, alpha_ref = body_rate_from_euler_zyx(rpy, rates, accels)
    np.testing.assert_allclose(omega, omega_ref, rtol=0, atol=32 * EPS)
    np.testing.assert_allclose(alpha, alpha_ref, rtol=0, atol=128 * EPS)


# --------------------------------------------------------------------------------------------------
# random-manoeuvre
# --------------------------------------------------------------------------------------------------

MANOEUVRE = {
    "kind": "random-manoeuvre",
    "rotation": {
        "mean_rpy_deg": [5.0, -3.0, 40.0],
        "amplitude_deg": [30.0, 20.0, 120.0],
        "frequency_hz": [0.05, 0.8],
        "terms": 5,
    },
    "translation": {"amplitude_m": [40.0, 30.0, 4.0], "frequency_hz": [0.01, 0.3], "terms": 4},
}


def manoeuvre(seed=0, **overrides):
    return scenario_from_dict(
        {"duration_s": 60.0, "rate_hz": 200.0, "site": SITE, **MANOEUVRE, "seed": seed, **overrides}
    ).spec


def test_random_manoeuvre_kinematics():
    s = manoeuvre(seed=3)
    rotation, translation = s.sines()

    def majorant(amplitude, omega, offset=0.0):
        # |x⁽ⁿ⁾| ≤ Σ A ωⁿ for a sum of sinusoids.
        return Majorant.of_derivatives(
            [abs(offset) + amplitude.sum()] + [(amplitude * omega**n).sum() for n in range(1, 7)]
        )

    roll, pitch, yaw = (majorant(a, w) for a, w in zip(rotation[0], rotation[1]))
    position = [majorant(a, w) for a, w in zip(translation[0], translation[1])]
    xy = Majorant(np.maximum(position[0].c, position[1].c))
    bounds = euler_motion_bounds(roll, pitch, yaw, xy, position[2])
    traj = s.trajectory(uniform_times(11.0, 10.0, h=2.0**-11))
    assert_kinematics(traj, bounds, sharp=1e-3)


def test_random_manoeuvre_same_seed_is_bit_identical_and_seeds_differ():
    t = np.arange(20_001) / 200.0
    a, b, c = (
        manoeuvre(seed=7).trajectory(t),
        manoeuvre(seed=7).trajectory(t),
        manoeuvre(seed=8).trajectory(t),
    )
    for name in ("q_wb", "omega_b", "alpha_b", "specific_force_b", "pos_w", "vel_w", "mag_b"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
        assert not np.allclose(getattr(a, name), getattr(c, name)), name


def test_random_manoeuvre_draws_within_bounds():
    s = manoeuvre(seed=11)
    (a_rot, w_rot, p_rot), (a_tr, w_tr, _) = s.sines()
    np.testing.assert_allclose(a_rot.sum(axis=1), np.radians(MANOEUVRE["rotation"]["amplitude_deg"]), rtol=4 * EPS)
    np.testing.assert_allclose(a_tr.sum(axis=1), MANOEUVRE["translation"]["amplitude_m"], rtol=4 * EPS)
    assert a_rot.shape == (3, 5) and a_tr.shape == (3, 4) and (a_rot >= 0).all()
    f = w_rot / (2 * np.pi)
    assert (f >= 0.05).all() and (f <= 0.8).all() and (p_rot >= 0).all() and (p_rot < 2 * np.pi).all()
    # The attitude stays within the bounds around the mean.
    m = s.world_motion(np.arange(60_001) / 100.0)
    rpy = np.degrees(np.unwrap(euler_zyx_from_quat(m.q_wb), axis=0))
    assert np.all(np.abs(rpy[:, :2] - MANOEUVRE["rotation"]["mean_rpy_deg"][:2]) <= np.array([30.0, 20.0]) + 1e-9)


# --------------------------------------------------------------------------------------------------
# car
# --------------------------------------------------------------------------------------------------

CAR = {
    "kind": "car",
    "drive": {"initial_yaw_deg": 30.0, "accel_m_s2": 3.0, "brake_m_s2": 5.0},
    "legs": [
        {"speed_m_s": 8.0, "hold_s": 1.0},
        {"speed_m_s": 14.0, "hold_s": 1.5},
        {"speed_m_s": 0.0, "hold_s": 2.0},
    ],
    # Peak lateral acceleration (16/5) Δψ v² / L: 3.2 m/s² at 8 m/s, 3.6 m/s² at 14 m/s. The car
    # stops at 196 m, after both turns.
    "turns": [
        {"start_m": 15.0, "length_m": 100.0, "angle_deg": 90.0},
        {"start_m": 120.0, "length_m": 60.0, "angle_deg": -20.0},
    ],
    "bumps": [
        {"at_s": 4.0, "heave_m": 0.03, "nose_up_deg": 0.8, "rise_s": 0.05},
        {"at_s": 9.0, "heave_m": -0.02, "nose_up_deg": -0.5, "rise_s": 0.08},
    ],
    "suspension": {
        "roll_deg_per_m_s2": 0.6,
        "pitch_deg_per_m_s2": 0.4,
        "heave_frequency_hz": 1.3,
        "pitch_frequency_hz": 1.7,
        "damping_ratio": 0.35,
    },
}


def car(**overrides):
    return scenario_from_dict({"duration_s": 30.0, "rate_hz": 100.0, "site": SITE, **CAR, **overrides}).spec


def car_bounds(s) -> DerivativeBounds:
    """Majorants of the car's motion from its legs, turns, bumps and suspension (see CarSpec)."""
    sus = s.suspension
    speeds = [0.0] + [leg.speed_m_s for leg in s.legs]
    v_max = max(speeds)
    # v⁽ⁿ⁾ = Δv S⁽ⁿ⁾/Tⁿ with T = 16|Δv|/(5 a_peak): bound over the legs.
    changes = [
        (abs(b - a), 16 * abs(b - a) / (5 * (s.drive.accel_m_s2 if b > a else s.drive.brake_m_s2)))
        for a, b in zip(speeds, speeds[1:])
        if b != a
    ]
    v = Majorant.of_derivatives(
        [v_max] + [max([dv * step_bound(n) / T**n for dv, T in changes], default=0.0) for n in range(1, 7)]
    )
    distance = v.integral()  # majorises s(t0 + τ) − s(t0)
    # κ⁽ⁿ⁾(s) = Δψ S⁽ⁿ⁺¹⁾/L^(n+1); ψ′ = κ.
    kappa_s = Majorant.of_derivatives(
        [
            max(
                [abs(np.radians(tr.angle_deg)) * step_bound(n + 1) / tr.length_m ** (n + 1) for tr in s.turns],
                default=0.0,
            )
            for n in range(7)
        ]
    )
    kappa = kappa_s.compose(distance)
    heading_s = kappa_s.integral()
    yaw = Majorant([np.pi]) + heading_s.compose(distance)

    # Bump transients: g⁽ᵈ⁾ ≤ Σ |c_m| |μ_m|ᵈ / peak.
    def transient(frequency, scale):
        out = Majorant([0.0])
        for bump in s.bumps:
            g = SuspensionTransient(frequency, sus.damping_ratio, bump.rise_s)
            out = out + Majorant.of_derivatives(
                [abs(scale(bump)) * np.abs(g._c * g._mu**d).sum() / g.peak for d in range(7)]
            )
        return out

    roll = np.radians(sus.roll_deg_per_m_s2) * kappa * v * v
    pitch = np.radians(sus.pitch_deg_per_m_s2) * v.derivative() + transient(
        sus.pitch_frequency_hz, lambda b: np.radians(b.nose_up_deg)
    )
    heave = transient(sus.heave_frequency_hz, lambda b: b.heave_m)
    # Road position: X′(s) = (cos ψ, sin ψ) ≪ exp(Δψ(δs)), so X(s0 + δ) − X(s0) ≪ ∫ exp(Δψ).
    road = heading_s.trig().integral()
    return euler_motion_bounds(roll, pitch, yaw, road.compose(distance), heave)


def test_car_kinematics_speed_changes_and_turns():
    s = car(bumps=[])
    traj = s.trajectory(uniform_times(0.0, 29.0, h=2.0**-11))
    assert_kinematics(traj, car_bounds(s), sharp=1e-3)


def test_car_kinematics_bumps():
    # Straight road at constant speed: the suspension transients alone. Their majorants ignore the
    # cancellations of the smooth onset, hence the finer step.
    s = car(legs=[{"speed_m_s": 10.0, "hold_s": 30.0}], turns=[])
    traj = s.trajectory(uniform_times(3.5, 7.0, h=2.0**-14))
    assert_kinematics(traj, car_bounds(s), sharp=1e-3)


def test_car_speed_profile_heading_and_stop():
    s = car()
    t = uniform_times(0.0, 30.0, h=2.0**-8)
    traj = s.trajectory(t)
    speed = traj.extras["speed_m_s"]
    np.testing.assert_allclose(np.linalg.norm(traj.vel_w[:, :2], axis=1), speed, rtol=0, atol=16 * EPS * 20)
    # Each speed change Δv takes 16 |Δv| / (5 a_peak); then the speed holds.
    ramps = [16 * 8 / (5 * 3.0), 16 * 6 / (5 * 3.0), 16 * 14 / (5 * 5.0)]
    holds = [1.0, 1.5, 2.0]
    start = 0.0
    for ramp, hold, target in zip(ramps, holds, [8.0, 14.0, 0.0]):
        inside = (t > start + ramp + 1e-9) & (t < start + ramp + hold - 1e-9)
        np.testing.assert_allclose(speed[inside], target, rtol=0, atol=64 * EPS * 20)
        start += ramp + hold
    # The peak longitudinal acceleration is accel_m_s2 speeding up and brake_m_s2 slowing down.
    m = s.world_motion(t)
    along = np.einsum("ij,ij->i", m.acc_w[:, :2], m.vel_w[:, :2]) / np.maximum(speed, 1e-12)
    assert along.max() == pytest.approx(3.0, rel=1e-4) and along[speed > 0.5].min() == pytest.approx(-5.0, rel=1e-4)
    # After both turns the heading is 30 + 90 − 20 = 100°; stopped, the car stays put.
    stopped = t > start - holds[-1] + 1e-9
    yaw = euler_zyx_from_quat(traj.q_wb[stopped])[:, 2]
    np.testing.assert_allclose(np.degrees(yaw), 100.0, rtol=0, atol=1e-12)
    assert np.ptp(traj.pos_w[stopped], axis=0).max() == 0.0 and not traj.vel_w[stopped].any()


def test_car_roll_follows_lateral_and_pitch_longitudinal_acceleration():
    s = car(bumps=[])
    t = uniform_times(0.0, 15.0, h=2.0**-8)
    m = s.world_motion(t)
    roll, pitch, yaw = euler_zyx_from_quat(m.q_wb).T
    left = np.c_[-np.sin(yaw), np.cos(yaw), 0 * yaw]
    forward = np.c_[np.cos(yaw), np.sin(yaw), 0 * yaw]
    lateral = np.einsum("ij,ij->i", m.acc_w, left)
    longitudinal = np.einsum("ij,ij->i", m.acc_w, forward)
    np.testing.assert_allclose(roll, np.radians(0.6) * lateral, rtol=0, atol=1e-14)  # outward lean
    np.testing.assert_allclose(pitch, -np.radians(0.4) * longitudinal, rtol=0, atol=1e-14)  # dive when braking
    assert lateral.max() > 3.0  # the 90° left turn at speed


def test_car_bump_heave_peaks_at_the_given_height():
    s = car()
    t = uniform_times(3.0, 6.0, h=2.0**-12)
    m = s.world_motion(t)
    z = m.pos_w[:, 2]
    first = t < 9.0
    assert z[first].max() == pytest.approx(0.03, rel=1e-6)
    # C³ onset: z, ż, z̈ vanish where the wheels meet the bump.
    at = np.searchsorted(t, 4.0)
    assert np.abs([z[at], m.vel_w[at, 2], m.acc_w[at, 2]]).max() <= 1e-12
    assert np.all(z[t < 4.0] == 0.0)


def test_road_position_through_turns_matches_quadrature():
    turns = [
        Turn(start_m=15.0, length_m=50.0, angle_deg=120.0),
        Turn(start_m=80.0, length_m=25.0, angle_deg=-200.0),
    ]
    road = Road(turns, np.radians(-20.0))
    s = np.array([0.0, 10.0, 15.0, 33.3, 64.9, 70.0, 80.0, 97.2, 105.0, 300.0])
    psi, cos, sin, _, _, _, x, y = road(s)
    np.testing.assert_allclose(cos, np.cos(psi), rtol=0, atol=2 * EPS)
    np.testing.assert_allclose(sin, np.sin(psi), rtol=0, atol=2 * EPS)

    def heading(d):
        return road(np.array([d]))[0][0]

    # Reference: adaptive quadrature of (cos ψ, sin ψ) with the turn ends as break points. Tolerance: its
    # own error estimate plus the round-off of positions of that size.
    for d, xe, ye in zip(s, x, y):
        for position, trig in ((xe, np.cos), (ye, np.sin)):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", IntegrationWarning)  # it reaches round-off and says so
                expected, error = quad(
                    lambda u: trig(heading(u)),
                    0,
                    d,
                    points=[15, 65, 80, 105],
                    limit=400,
                    epsabs=1e-14,
                    epsrel=1e-14,
                )
            assert abs(position - expected) <= error + 16 * EPS * max(d, 1)
    np.testing.assert_allclose(np.degrees(psi[-1]), -20 + 120 - 200, atol=1e-12)
    # Curvature is the smooth pulse Δψ S′/L: peak (16/5) Δψ / L mid-turn.
    kappa = road(np.array([40.0]))[3][0]
    assert kappa == pytest.approx(3.2 * np.radians(120.0) / 50.0, rel=1e-14)
    assert smooth_step(np.array([0.5]), 1)[1][0] == 3.2


@pytest.mark.parametrize(
    "overrides, key",
    [
        ({"seed": 1.5}, "seed"),
        ({"seed": True}, "seed"),
        ({"seed": -1}, "seed"),
        ({"rotation": {"frequency_hz": [1.0, 0.5]}}, "rotation.frequency_hz"),
        ({"rotation": {"terms": 0}}, "rotation.terms"),
        ({"translation": {"amplitude_m": [1.0, -1.0, 0.0]}}, "translation.amplitude_m"),
        ({"translation": {"amplitude": [1.0, 1.0, 0.0]}}, "translation.amplitude"),
    ],
)
def test_random_manoeuvre_bad_keys(overrides, key):
    with pytest.raises(ConfigError) as err:
        scenario_from_dict({"duration_s": 1.0, "rate_hz": 10.0, **MANOEUVRE, **overrides}, name="m.toml")
    assert err.value.key == key


@pytest.mark.parametrize(
    "overrides, key",
    [
        ({"legs": []}, "legs"),
        ({"legs": [{"speed_m_s": -3.0, "hold_s": 1.0}]}, "legs[0].speed_m_s"),
        ({"legs": [{"speed_kmh": 30.0, "hold_s": 1.0}]}, "legs[0].speed_kmh"),
        (
            {
                "turns": [
                    {"start_m": 10.0, "length_m": 50.0, "angle_deg": 90},
                    {"start_m": 40.0, "length_m": 5.0, "angle_deg": 9},
                ]
            },
            "turns",
        ),
        ({"turns": [{"start_m": 10.0, "length_m": 0.0, "angle_deg": 90}]}, "turns[0].length_m"),
        ({"suspension": {"damping_ratio": 1.0}}, "suspension.damping_ratio"),
        ({"bumps": [{"at_s": 1.0, "rise_s": 0.0}]}, "bumps[0].rise_s"),
    ],
)
def test_car_bad_keys(overrides, key):
    with pytest.raises(ConfigError) as err:
        scenario_from_dict({"duration_s": 1.0, "rate_hz": 10.0, **CAR, **overrides}, name="car.toml")
    assert err.value.key == key

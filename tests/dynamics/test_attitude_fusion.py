"""The reference below the crossover, the gyro above it (``gyroemu.dynamics.attitude_fusion``).

Bounds from the construction: a constant rate is integrated exactly by the midpoint rule, so with an
exact reference the result is the reference to round-off; white reference noise passes the zero-phase
second-order low-pass with the variance fraction 2 f_c/f_s · ∫₀^∞ dx/(1+x⁴)² = 2 f_c/f_s · 3π/(8√2);
a gyro bias integrates into a ramp of δ, which a zero-phase filter of unit gain at DC passes whole away
from the ends (its transients there decay as exp(−2π ζ f_c t), ζ = 1/√2).
"""

from __future__ import annotations

import numpy as np
import pytest

from gyroemu.dynamics.attitude_fusion import complementary_attitude
from gyroemu.dynamics.rotation import quat_angle, quat_from_rotvec, quat_multiply

EPS = np.finfo(float).eps
FS = 200.0


def _spin(duration: float, rate=(0.3, -0.5, 1.2)):
    """A constant body rate from a tilted start: q(t) = q₀ ⊗ exp(ω t / 2), exactly."""
    t = np.arange(int(duration * FS) + 1) / FS
    w = np.broadcast_to(np.asarray(rate, float), (len(t), 3))
    q0 = quat_from_rotvec([0.2, -0.1, 0.7])
    return t, quat_multiply(q0, quat_from_rotvec(t[:, None] * w)), np.array(w)


def test_an_exact_rate_and_reference_give_the_reference_to_round_off():
    t, q, w = _spin(20.0)
    fused = complementary_attitude(t, q, w, 1.0)
    # each of the N steps rounds at a few ε; the angle grows at most linearly in N
    assert np.max(quat_angle(fused, q)) < 20 * len(t) * EPS


def test_white_reference_noise_is_filtered_to_its_low_pass_share():
    t, q, w = _spin(120.0)
    rng = np.random.default_rng(4)
    sigma = np.radians(0.05)
    noisy = quat_multiply(q, quat_from_rotvec(sigma * rng.standard_normal((len(t), 3))))
    fc = 1.0
    fused = complementary_attitude(t, noisy, w, fc)
    interior = slice(int(5 * FS), -int(5 * FS))
    # per axis σ_out² = σ² · 2 f_c / f_s · 3π/(8√2); the angle's mean square is the sum of three axes
    expected = sigma * np.sqrt(3 * 2 * fc / FS * 3 * np.pi / (8 * np.sqrt(2)))
    rms = np.sqrt(np.mean(quat_angle(fused, q)[interior] ** 2))
    # about 2 f_c T = 220 independent stretches: the RMS to ±5 %, held at ±25 % (5σ)
    assert 0.75 * expected < rms < 1.25 * expected, (rms, expected)
    assert rms < 0.15 * np.sqrt(3) * sigma  # the reference's noise itself is gone but for that share


def test_a_gyro_bias_is_taken_out_by_the_reference():
    # turning about the bias's own axis, R_wb b is constant: the bias integrates into an exact ramp of δ
    axis = np.array([0.3, -0.2, 0.5]) / np.linalg.norm([0.3, -0.2, 0.5])
    t, q, w = _spin(60.0, rate=1.2 * axis)
    bias = np.radians(0.4) * axis  # 0.4 °/s: a consumer MEMS's
    fused = complementary_attitude(t, q, w + bias, 1.0)
    drift = np.linalg.norm(bias) * t[-1]  # what the bias alone integrates to: 24°
    interior = slice(int(3 * FS), -int(3 * FS))
    # the ramp passes whole inside; the end transients, at most the drift, decay by exp(−2π ζ f_c 3 s)
    bound = drift * np.exp(-2 * np.pi * 3.0 / np.sqrt(2)) + 1e3 * len(t) * EPS
    assert np.max(quat_angle(fused, q)[interior]) < bound


def test_gaps_in_the_reference_are_bridged_and_rows_before_it_stay_empty():
    t, q, w = _spin(10.0)
    ref = q.copy()
    ref[:50] = np.nan
    ref[400:460] = np.nan
    fused = complementary_attitude(t, ref, w, 1.0)
    assert np.isnan(fused[:50]).all() and np.isfinite(fused[50:]).all()
    assert np.max(quat_angle(fused[50:], q[50:])) < 20 * len(t) * EPS


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"crossover_hz": 150.0}, "half the sample rate"),
        ({"crossover_hz": 0.0}, "half the sample rate"),
        ({"omega_b": np.zeros((5, 3))}, "omega_b"),
    ],
)
def test_bad_arguments_are_refused(kwargs, match):
    t, q, w = _spin(1.0)
    args = {"t": t, "q_ref": q, "omega_b": w, "crossover_hz": 1.0} | kwargs
    with pytest.raises(ValueError, match=match):
        complementary_attitude(**args)


def test_a_bias_under_fast_rocking_is_taken_out_in_world_axes():
    """Rocking about x at f = 3 Hz (±30°, faster than the crossover) with a bias along z: in world axes
    R_wb b = |b| (0, −sin θ, cos θ) integrates into a ramp (the mean of cos θ) and harmonics of f of
    amplitude at most |b| / (2π f) each (sin θ and cos θ are bounded by 1, and their harmonics' sum too),
    which the 1-Hz low-pass removes: the error stays below 2 |b| / (2π f) plus the end transients. Taken
    in body axes instead, the ramp would be modulated at f and removed with it: tenths of a radian."""
    f, amplitude = 3.0, np.radians(30.0)
    t = np.arange(int(60.0 * FS) + 1) / FS
    theta = amplitude * np.sin(2 * np.pi * f * t)
    q = quat_from_rotvec(theta[:, None] * np.array([1.0, 0.0, 0.0]))
    w = (amplitude * 2 * np.pi * f * np.cos(2 * np.pi * f * t))[:, None] * np.array([1.0, 0.0, 0.0])
    b = np.radians(0.4)
    fused = complementary_attitude(t, q, w + np.array([0.0, 0.0, b]), 1.0)
    interior = slice(int(3 * FS), -int(3 * FS))
    ends = b * t[-1] * np.exp(-2 * np.pi * 3.0 / np.sqrt(2))
    # the midpoint rule's own error on the rocking: |θ'''| h² / 12 per unit time, over 60 s
    integration = amplitude * (2 * np.pi * f) ** 3 / (FS**2 * 12) * t[-1]
    bound = 2 * b / (2 * np.pi * f) + ends + integration
    assert np.max(quat_angle(fused, q)[interior]) < bound, (np.max(quat_angle(fused, q)[interior]), bound)

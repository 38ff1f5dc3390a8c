"""The per-sample variances ``/imu`` carries in ``angular_velocity_covariance`` and
``linear_acceleration_covariance`` (REP 145: the variance of each measurement, on the diagonal).

For a sensor axis sampled every ``T = 1/rate_hz`` seconds, what is new in every sample is:

- **white noise** of Allan reading ``N`` (IEEE 952's random-walk coefficient, the Allan deviation at
  1 s; README "Noise density"): its samples are means over ``T`` of a white process of two-sided
  density ``N²``, variance ``σ² = N²/T`` (IEEE 952-1997, annex C; El-Sheimy et al., IEEE TIM 57(1),
  2008, eq. 12). For the gyro ``N`` is :attr:`Device.gyro_noise_density`, the total at the output
  (the mechanism's own noise, the added noise and a rate quantiser's share); for the accelerometer it
  is the added noise, and the quantiser's share follows;
- **rate (output) quantisation** of step ``q``, dithered by that noise: ``q²/12`` (uniform error;
  Widrow & Kollár, *Quantization Noise*, 2008, ch. 4; the device refuses a quantiser its noise does not
  dither). It is already inside the gyro's ``N²/T``, as the device budgets it;
- **integrating quantisation** of step ``q_i`` (a pulse-counting output): the rate is the difference
  of two counts over ``T``, each off by an independent uniform error, ``2 (q_i/T)²/12``. The same
  holds for a mechanism that counts its own pulses (a ring laser's fringes,
  :meth:`GyroMechanism.output_angle_quantum`): ``navigation_rlg``'s fringe of 2.26″ at 1 kHz gives
  4.5·10⁻³ rad/s, far above its white noise (measured on a static run of 20 000 samples: within 1 %);
- an output **low-pass** (``bandwidth_hz``) scales the white variance ahead of the quantiser by its
  noise-power gain ``C P Cᵀ + D²`` (``P`` the steady state of its state-space form);
- the gyro **mechanism's own noise** (``N_mech``, :attr:`Device.intrinsic_noise_density`) is white at
  low frequencies but goes through the mechanism's response ``H(f)`` before the output averages it
  over ``T``, whose transfer is ``sinc(fT)``; a sample's variance is then
  ``N_mech² ∫ |H(f)|² sinc²(fT) df`` (two-sided density ``N²``; Papoulis & Pillai, *Probability,
  Random Variables and Stochastic Processes*, 4th ed., §9-2: the output of a linear system has
  ``S_y = S_x |H|²``), i.e. ``g N_mech²/T`` with ``g = T ∫ |H|² sinc² df`` (``g = 1`` for ``H = 1``).
  The MEMS mechanism gives ``H`` (:meth:`rate_response`: its demodulator filter, 4th order at 500 Hz);
  ``consumer_mems`` at 1 kHz has ``g = 0.79``, so its per-sample variance is 2.3 % below ``N²/T``
  (measured on a static run of 420 000 samples: 2.2–2.4 % on the three axes). Other kinds are taken
  as white (``g = 1``). With an output low-pass as well, the mechanism's share is taken through both
  gains as if it were white (an approximation; no preset has both).

Bias instability, random walks, temperature and turn-on bias are not in the covariance: they are
correlated from sample to sample (REP 145 asks for the measurement's variance; a filter models them as
states). Nothing here draws random numbers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    from gyroemu.sensors.imu import Device

__all__ = ["measurement_variances", "white_variance", "mechanism_noise_gain"]


def _low_pass_gain(period: float, bandwidth_hz: float, order: int) -> float:
    """Variance out over variance in of a Butterworth low-pass of ``order`` at ``bandwidth_hz`` sampled
    every ``period`` s, for white noise: ``C P Cᵀ + D²``, ``P = A P Aᵀ + B Bᵀ`` (discrete Lyapunov)."""
    import scipy.linalg
    import scipy.signal

    b, a = scipy.signal.butter(order, bandwidth_hz, btype="low", fs=1.0 / period)
    A, B, C, D = scipy.signal.tf2ss(b, a)
    P = scipy.linalg.solve_discrete_lyapunov(A, B @ B.T)
    return float((C @ P @ C.T)[0, 0] + D[0, 0] ** 2)


def mechanism_noise_gain(mechanism: object, period: float) -> float:
    """``g = T ∫ |H(f)|² sinc²(fT) df`` of a gyro mechanism with a ``rate_response(f)`` (1 otherwise):
    the share of ``N_mech²/T`` its noise keeps in a sample averaged over ``period`` s (module notes).
    Trapezoidal rule on ``0 ≤ f ≤ 50/T`` (the integrand falls as ``f⁻²`` or faster; the tail beyond
    ``50/T`` holds less than ``1/(π² · 50)`` of the whole, a 2·10⁻³ bound, 10× less for a filtered ``H``)."""
    response = getattr(mechanism, "rate_response", None)
    if response is None:
        return 1.0
    f = np.linspace(0.0, 50.0 / period, 200_001)
    h2 = np.abs(np.asarray(response(f))) ** 2
    return float(2.0 * period * np.trapezoid(h2 * np.sinc(f * period) ** 2, f))


def white_variance(
    density: ArrayLike,
    period: float,
    *,
    output_lsb: float | None = None,
    lsb_included: bool = False,
    integral_lsb: float | None = None,
    counter_lsb: float | None = None,
    bandwidth_hz: float | None = None,
    filter_order: int = 1,
    shaped_density: float = 0.0,
    shaped_gain: float = 1.0,
) -> NDArray[np.float64]:
    """Per-sample variance (3,) of an axis triad whose white noise has Allan reading ``density`` (3,)
    (unit/√Hz, i.e. unit·√s) sampled every ``period`` s; see the module's notes for each term.
    ``lsb_included``: ``density`` already holds the rate quantiser's share ``output_lsb² T/12``;
    ``shaped_density`` of it (the mechanism's own noise) keeps only ``shaped_gain`` of its ``N²/T``.
    ``integral_lsb`` and ``counter_lsb``: the steps of the error layer's angle quantiser and of the
    mechanism's own counter, in the unit of ``density`` × s."""
    density = np.asarray(density, dtype=float)
    quantiser = output_lsb**2 / 12.0 if output_lsb else 0.0
    white = density**2 / period - (quantiser if lsb_included else 0.0)  # σ² = N²/T
    white = white - (1.0 - shaped_gain) * shaped_density**2 / period
    if bandwidth_hz is not None and bandwidth_hz < 0.5 / period:
        white = white * _low_pass_gain(period, bandwidth_hz, filter_order)
    # 2 (q/T)²/12 for each counter: a rate is two counts' difference over T, each off by U(0, q)
    counts = sum((2.0 * (lsb / period) ** 2 / 12.0 for lsb in (integral_lsb, counter_lsb) if lsb), 0.0)
    return white + quantiser + counts


def measurement_variances(device: object) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """``(gyro (3,) (rad/s)², accel (3,) (m/s²)²)``: the per-sample variances of a ``Device``'s output
    at its rate; None for anything that is not a Device (a config's text, None)."""
    spec = getattr(device, "spec", None)
    if spec is None or not hasattr(device, "gyro_noise_density"):
        return None
    period = 1.0 / float(spec.rate_hz)
    gyro_model = cast("Device", device).gyro_errors  # a Device: it has a spec and a noise density
    mechanism = cast("Device", device).mechanism
    accel_model = cast("Device", device).accel_errors
    gyro = white_variance(
        device.gyro_noise_density,
        period,
        output_lsb=gyro_model.output_lsb,
        lsb_included=True,
        integral_lsb=gyro_model.integral_lsb,
        counter_lsb=mechanism.output_angle_quantum(),
        bandwidth_hz=gyro_model.bandwidth_hz,
        filter_order=gyro_model.filter_order,
        shaped_density=float(getattr(device, "intrinsic_noise_density", 0.0)),
        shaped_gain=mechanism_noise_gain(mechanism, period),
    )
    accel = white_variance(
        accel_model.noise_density,
        period,
        output_lsb=accel_model.output_lsb,
        integral_lsb=accel_model.integral_lsb,
        bandwidth_hz=accel_model.bandwidth_hz,
        filter_order=accel_model.filter_order,
    )
    return gyro, accel

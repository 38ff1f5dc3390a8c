"""gyroemu's attitude filter: a multiplicative (error-state) extended Kalman filter on filterpy.

The nominal state is the attitude ``q_wb``, the gyro bias ``b`` and the gyro's scale-factor and misalignment
errors ``M``, and the low-passed horizontal acceleration ``â`` (a Gauss–Markov process, considered, not
estimated: ``â`` stays 0); the Kalman filter (filterpy's ``KalmanFilter``, dim_x = 17) carries their errors
``(δθ, δb, δM, δa)``, ``δθ`` in world axes. The gyro drives a strapdown integration at every sample; every
window (20 ms by default) the error covariance is propagated over the window, the window's measurements
update the error state, and the error is folded back into the nominal state (Markley & Crassidis,
*Fundamentals of Spacecraft Attitude Determination and Control*, §6.2; the models are in
:mod:`gyroemu.pipelines.estimation.mekf_kernels`):

* **gravity direction** from the specific force in the world frame through two low-passes of
  ``accel_tau_s``: it corrects inclination only (its ``H`` has no heading column). Non-gravitational
  acceleration (translation, tapping, vibration) is what the low-passes leave of it, noise of density
  ``motion_accel_density`` plus how far ``|ā|`` strays from gravity, plus what the innovations show
  beyond the model (``accel_adapt``); every measurement is taken (no gate);
* **heading** from the magnetic field averaged in the world frame, a scalar measurement whose gain is
  constrained to never touch inclination; fields whose norm or dip differ from the reference
  (learned at the start) are a disturbance and skipped, and a χ² gate catches the rest;
* **rest**: a still gyro reads its bias (plus Earth's rate, taken out when the latitude is known, which
  then also finds north for a gyro good enough to see it).

Initialisation uses the first ``init_s`` of the first block: tilt from the mean specific force,
heading from the mean field (9D), from Earth's rate (6D, known latitude, a gyro whose gyrocompass
heading is better than 20°, at rest), or zero. The noise figures come from the device where they are
known (:class:`~gyroemu.pipelines.estimation.protocol.DeviceNoise`) and from :class:`MekfParams`' defaults
otherwise: one parameter set for every log.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np
from filterpy.kalman import KalmanFilter
from numpy.typing import ArrayLike, NDArray

from gyroemu.dynamics.earth import EARTH_RATE
from gyroemu.dynamics.rotation import quat_from_rotvec, quat_multiply, quat_rotate

from . import mekf_kernels as kern
from .peers import initial_attitude
from .protocol import Estimate, FilterSetup

__all__ = ["Mekf", "MekfParams", "initial_state"]

_DEG = np.pi / 180


_DIVIDING = frozenset({"window_s", "accel_tau_s", "accel_gm_tau_s", "mag_window_s", "rest_tau_s"})
""":class:`MekfParams` whose value divides (windows and time constants): more than 0."""


@dataclass(frozen=True)
class MekfParams:
    """The filter's parameters, SI. The defaults serve any log; the noise figures of a known device
    replace the first seven (and set ``turn_noise`` to 0: its scale states then model all it turns), and a
    simulated site's field its ``heading_sigma`` (:meth:`for_setup`).

    Attributes
    ----------
    gyro_noise_density : float
        White rate noise N, rad/s/√Hz (angle random walk).
    gyro_bias_sigma : float
        Turn-on bias uncertainty, rad/s.
    gyro_bias_random_walk, gyro_bias_random_walk_vertical : float
        Bias random walk, rad/s/√s, across and along the body's vertical ``Rᵀ e_z``; a known device sets
        both to its rate random walk plus its bias instability spread over 100 s. Across (what gravity
        sees within seconds) the default is VQF's for any gyro, 0.01 °/s/√s (``biasForgettingTime``: the
        bias uncertainty grows from 0 to 0.1 °/s in 100 s; Laidig & Seel 2023): an unknown MEMS gyro's bias
        moves with temperature and, as the body turns gravity between its axes, with its g-sensitivity
        (datasheets: 0.01–0.1 °/s/g); the earlier 0.0011 °/s/√s held BROAD's bias still through two
        minutes of handling, where VQF's estimate moves by 0.02 °/s (README). Along the vertical, which
        only the field and rests see, it stays 2·10⁻⁵ rad/s/√s: a bias free to move there learns the
        field's own errors (a magnet's, the lab's) as gyro drift and carries them on (the twin of BROAD's
        trial 27: 9D 0.5° → 2.5° with the vertical as free as the rest).
    accel_noise_density : float
        White specific-force noise, m/s²/√Hz.
    mag_noise_density : float
        White magnetometer noise, T/√Hz.
    scale_factor_sigma, misalignment_sigma : float
        Initial uncertainty (1σ) of each gyro axis's scale-factor error, relative, and of each of the six
        misalignments, rad: the prior of ``M``'s diagonal and off-diagonal elements.
    scale_factor_random_walk : float
        How fast ``M`` may wander (temperature, ageing), 1/√s.
    turn_noise : float
        Rotation error the scale-factor states do not model (nonlinearity, stamps a little off), relative:
        every radian turned adds ``turn_noise²`` rad² of attitude variance.
    window_s : float
        Window over which the covariance is propagated, s.
    accel_tau_s : float
        Time constant of each of the two low-passes the world-frame specific force goes through, s.
    mag_window_s : float
        Window over which the field is averaged in the world frame, s.
    motion_accel_density : float
        Non-gravitational acceleration always allowed for, as a white-noise density, m/s²/√Hz (its
        correlation over the window is what makes this a density and not a level). 0.4/√2 ≈ 0.283: the 0.4
        chosen before 2026-11-27 (was 0.3, BROAD's low-passed residual; the simulated smooth manoeuvre's
        translation needs 0.4 for a covariance that tells the truth; BROAD's online figures moved by 0.02°,
        README), restated in the density convention of the accelerometer's own noise (the variance through
        the low-passes was then taken as N²/(8τ), half of :func:`mekf_kernels.double_lowpass_variance`).
    motion_gain : float
        Weight of the window's squared deviation of ``|a|`` from gravity in the gravity noise.
    accel_gm_sigma, accel_gm_process_sigma, accel_gm_tau_s : float
        The low-passed horizontal non-gravitational acceleration as a first-order Gauss–Markov process of
        correlation time ``accel_gm_tau_s``, s: its prior standard deviation, m/s² (the acceleration the
        first samples took in, which the initial tilt holds: a prior correlated with it), and its
        stationary level, m/s² (motion slower than the low-passes, which they keep: a sway, a walk). It is
        a *consider* state (:func:`mekf_kernels.gravity_update`): never estimated, but its correlation over
        ``accel_gm_tau_s`` is in the covariance. The prior, 0.15 m/s² decaying over 10 s, with the white
        ``motion_accel_density`` puts the attitude NEES of the simulated runs in their χ² band
        (``tests/benchmarks/nees_check.py``); the stationary level is a floor, 2·10⁻⁴ m/s², that keeps P
        regular for the smoother: measured, 0.02–0.1 m/s² there leaves the consumer car or the tactical
        manoeuvre outside their bands on some seed sets (README, "Covariance"). Until 2026-11-26 a loop in
        the transition overwrote this process noise with the scale states' (10⁻¹⁰ T, about this floor).
    accel_adapt : float
        Weight of the gravity innovations' mean square beyond what the filter expects, added to the gravity
        noise (innovation-based adaptive estimation; :func:`mekf_kernels.gravity_adapt`); 0: off.
    accel_adapt_rise_s : float
        Time constant of that mean square as it rises, s (it falls over ``4 accel_tau_s``, as an ended
        acceleration leaves the low-passes): 0.5 s catches a car speeding up before the tilt has taken in
        much of it (with ``accel_tau_s``, 1 s, the car's tilt error doubled with the acceleration state).
    accel_gate : float
        Threshold of the adaptive gravity noise (``accel_adapt``), a χ²(2) quantile: the innovations' mean
        square counts once twice it exceeds this times its expected spread. There is no gate on the gravity
        measurement (the one of this name, with ``accel_timeout_s``, never fired and is gone since
        2026-11-27: docs/offline-attitude.md).
    mag_gate : float
        χ² gate of the heading (1 dof) innovation.
    mag_timeout_s : float
        How long heading rejections may last before a measurement is taken again, inflated onto the gate, s.
    heading_sigma, heading_correlation_s : float
        Heading error of the field's direction (residual soft iron, local anomalies, a moving
        sensor's changing surroundings), rad, and the time over which it is correlated, s.
    heading_motion_factor : float
        Factor on the heading measurement's variance when the body moved during its window (the field
        where the body moves may point elsewhere than where it rests); 1: the same everywhere.
    mag_norm_tolerance : float
        Relative change of the field's norm that marks a disturbance.
    mag_dip_tolerance : float
        Change of the dip angle that marks a disturbance, rad.
    hold_rate : float
        Rate uncertainty over a missing gyro sample (the last one is held), rad/s.
    rest_tau_s, rest_gyro, rest_accel, rest_time_s : float
        Rest detector: low-pass time constant (s), gyro (rad/s) and specific-force (m/s²) thresholds on
        the samples' deviation from their low-pass, time still before the rest measurement starts (s).
    rest_rate : float
        Rest detector: threshold on the low-passed, bias-corrected rate, rad/s. The rest measurement takes
        it for zero, so for a known gyro it is five times what noise and bias leave in it,
        ``5 √(N²/(2 τ_rest) + σ_b²)`` (at most the default): a slow turn the gyro can see (a car pitching
        as it speeds up, 0.1–0.3 °/s) is not learnt as bias.
    rest_sigma : float
        Residual-rate floor of the rest measurement, rad/s (Earth's rate is added when the latitude is
        unknown).
    rest_gate : float
        Gate on a rest window's mean rate against the mean of its stretch at rest, in units of the white
        noise's variance (:func:`mekf_kernels.rest_gate`): a rate that is not stationary is a slow turn (a
        car entering a bend) and rejected. 36 (6σ), not χ²(3)'s 16.3 (4σ): the rests of the BROAD twins
        (``gyroemu twin``) wander by 4–6σ, beyond white noise, and gating them cost the twin of trial 11
        twice its attitude error; 6σ still keeps the car's turn from being learnt as bias.
    init_s : float
        Samples averaged for the initial attitude, s.
    tilt_sigma0, heading_sigma0 : float
        Initial attitude uncertainties (1σ), rad.
    gyrocompass_s : float
        Samples at rest averaged to find north from Earth's rate at the start (6D, latitude known), s.
    """

    gyro_noise_density: float = 3e-4
    gyro_bias_sigma: float = 0.5 * _DEG
    gyro_bias_random_walk: float = 0.01 * _DEG
    gyro_bias_random_walk_vertical: float = 2e-5
    accel_noise_density: float = 2e-3
    mag_noise_density: float = 2e-7
    scale_factor_sigma: float = 0.01
    misalignment_sigma: float = 0.01
    scale_factor_random_walk: float = 1e-5
    turn_noise: float = 0.01
    window_s: float = 0.02
    accel_tau_s: float = 1.0
    mag_window_s: float = 1.0
    # 0.4 was chosen (on the NEES check) when the gravity noise took N²/(8τ) for the variance of white noise
    # through the double low-pass, half of what the density convention gives (N²/(4τ)); the same noise in
    # the documented convention is 0.4/√2, so the motion's share of R is as it was
    motion_accel_density: float = 0.4 / math.sqrt(2.0)
    motion_gain: float = 1.0
    accel_adapt: float = 1.0
    accel_adapt_rise_s: float = 0.5
    accel_gm_sigma: float = 0.15
    accel_gm_process_sigma: float = 2e-4
    accel_gm_tau_s: float = 10.0
    accel_gate: float = 13.8
    mag_gate: float = 10.8
    mag_timeout_s: float = 60.0
    heading_sigma: float = 5 * _DEG
    heading_correlation_s: float = 30.0
    heading_motion_factor: float = 1.0
    mag_norm_tolerance: float = 0.1
    mag_dip_tolerance: float = 10 * _DEG
    hold_rate: float = 1.0
    rest_tau_s: float = 0.5
    rest_gyro: float = 2 * _DEG
    rest_rate: float = 2 * _DEG
    rest_accel: float = 0.5
    rest_time_s: float = 1.5
    rest_sigma: float = 0.0
    rest_gate: float = 36.0
    init_s: float = 0.5
    tilt_sigma0: float = 2 * _DEG
    heading_sigma0: float = 10 * _DEG
    gyrocompass_s: float = 10.0

    def __post_init__(self) -> None:
        # every parameter is a standard deviation, a density, a duration, a gate or a tolerance; the
        # durations that divide (a window, a time constant) must be more than 0
        for f in fields(self):
            value = getattr(self, f.name)
            try:
                number = float(value)
            except (TypeError, ValueError):
                number = math.nan
            if not (math.isfinite(number) and number >= 0):
                raise ValueError(f"MekfParams.{f.name} = {value!r}: must be a finite number, 0 or more")
            if f.name in _DIVIDING and not number > 0:
                raise ValueError(f"MekfParams.{f.name} = {value!r}: must be more than 0")

    @classmethod
    def for_setup(cls, setup: FilterSetup, **overrides: float) -> MekfParams:
        """The defaults with the device's known noise figures in place, then ``overrides``."""
        noise = setup.noise
        known = {}
        if noise.gyro_noise_density is not None:
            known["gyro_noise_density"] = noise.gyro_noise_density
        if noise.gyro_bias_sigma is not None:
            known["gyro_bias_sigma"] = noise.gyro_bias_sigma
        if noise.gyro_rate_random_walk is not None or noise.gyro_bias_instability is not None:
            k = noise.gyro_rate_random_walk or 0.0
            bi = noise.gyro_bias_instability or 0.0
            known["gyro_bias_random_walk"] = float(np.sqrt(k**2 + bi**2 / 100.0))
            known["gyro_bias_random_walk_vertical"] = known["gyro_bias_random_walk"]  # alike about every axis
        if noise.gyro_noise_density is not None and noise.gyro_bias_sigma is not None:
            floor = np.sqrt(noise.gyro_noise_density**2 / (2 * cls.rest_tau_s) + noise.gyro_bias_sigma**2)
            known["rest_rate"] = float(min(cls.rest_rate, 5 * floor))
        if noise.gyro_scale_sigma is not None:
            known["scale_factor_sigma"] = noise.gyro_scale_sigma
            known["turn_noise"] = 0.0  # the device's scale and misalignment are all the states need
        if noise.gyro_misalignment_sigma is not None:
            known["misalignment_sigma"] = noise.gyro_misalignment_sigma
        if noise.accel_noise_density is not None:
            known["accel_noise_density"] = noise.accel_noise_density
        if noise.mag_noise_density is not None:
            known["mag_noise_density"] = noise.mag_noise_density
        if setup.field_heading_sigma is not None:
            known["heading_sigma"] = setup.field_heading_sigma
        return replace(cls(), **(known | overrides))

    def vector(self, setup: FilterSetup) -> np.ndarray:
        """The parameter vector the compiled kernels read (layout ``mekf_kernels.P_*``)."""
        p = np.zeros(kern.P_SIZE)
        p[kern.P_WINDOW] = self.window_s
        p[kern.P_WINDOW_N] = max(1, int(round(self.window_s * setup.rate_hz))) + 0.5  # + slack for jitter
        p[kern.P_ACC_TAU] = self.accel_tau_s
        p[kern.P_MAG_WINDOW] = self.mag_window_s
        p[kern.P_GYRO_NOISE] = self.gyro_noise_density
        p[kern.P_BIAS_RW] = self.gyro_bias_random_walk
        p[kern.P_BIAS_RW_VERTICAL] = self.gyro_bias_random_walk_vertical
        p[kern.P_SCALE_RW] = self.scale_factor_random_walk
        p[kern.P_TURN_NOISE] = self.turn_noise
        p[kern.P_HOLD_RATE] = self.hold_rate
        p[kern.P_ACC_NOISE] = self.accel_noise_density
        p[kern.P_MOTION] = self.motion_accel_density
        p[kern.P_MOTION_GAIN] = self.motion_gain
        p[kern.P_ACC_ADAPT] = self.accel_adapt
        p[kern.P_ACC_RISE] = self.accel_adapt_rise_s
        # a floor of 1e-9 rad (1e-8 m/s²) keeps P regular (the smoother inverts it) when the state is off
        p[kern.P_ACC_GM_PROCESS] = max(self.accel_gm_process_sigma / 9.80665, 1e-9)
        p[kern.P_ACC_GM_TAU] = self.accel_gm_tau_s
        p[kern.P_ACC_GATE] = self.accel_gate
        p[kern.P_HEADING_SIGMA] = self.heading_sigma
        p[kern.P_HEADING_CORR] = self.heading_correlation_s
        p[kern.P_HEADING_MOTION] = self.heading_motion_factor
        p[kern.P_MAG_NOISE] = self.mag_noise_density
        p[kern.P_MAG_NORM_TOL] = self.mag_norm_tolerance
        p[kern.P_MAG_DIP_TOL] = self.mag_dip_tolerance
        p[kern.P_MAG_GATE] = self.mag_gate
        p[kern.P_MAG_TIMEOUT] = self.mag_timeout_s
        p[kern.P_REST_TAU] = self.rest_tau_s
        p[kern.P_REST_GYRO] = self.rest_gyro
        p[kern.P_REST_RATE] = self.rest_rate
        p[kern.P_REST_GATE] = self.rest_gate
        p[kern.P_REST_ACCEL] = self.rest_accel
        p[kern.P_REST_TIME] = self.rest_time_s
        earth = EARTH_RATE if setup.latitude_rad is None else 0.0  # unmodelled Earth rate at rest
        # floor: with a noiseless gyro and no bias uncertainty (the ideal device) S would be singular
        p[kern.P_REST_SIGMA] = max(np.hypot(self.rest_sigma, earth), 1e-12)
        p[kern.P_USE_MAG] = 1.0 if setup.use_mag else 0.0
        p[kern.P_DECLINATION] = setup.declination_rad
        return p


def earth_rate_enu(setup: FilterSetup) -> np.ndarray:
    """Earth's rate in the ENU frame at the setup's latitude, rad/s (zeros when it is unknown)."""
    if setup.latitude_rad is None:
        return np.zeros(3)
    return EARTH_RATE * np.array([0.0, np.cos(setup.latitude_rad), np.sin(setup.latitude_rad)])


@dataclass
class InitialState:
    """Where a run starts: attitude, bias, covariance, and the references it learned."""

    q: np.ndarray
    b: np.ndarray
    P: np.ndarray
    slow: np.ndarray


def initial_state(
    t: ArrayLike,
    gyro: NDArray[np.float64],
    accel: NDArray[np.float64],
    mag: NDArray[np.float64] | None,
    setup: FilterSetup,
    params: MekfParams,
) -> InitialState:
    """The initial state from the first samples of a run (see the module's docstring)."""
    t = np.asarray(t, dtype=float)
    n = max(1, int(np.searchsorted(t, t[0] + params.init_s)))
    # Average in the first sample's axes: each sample turned back by the gyro's rotation since then.
    to_first = kern.rotations_since_first(t[:n], np.ascontiguousarray(gyro[:n], dtype=float))
    a_first = np.einsum("kij,kj->ki", to_first, accel[:n])
    a = np.nanmean(a_first, axis=0) if np.isfinite(a_first).any() else np.array([0.0, 0.0, 9.81])
    gravity = float(np.linalg.norm(a)) or 9.81
    q = initial_attitude(a)  # the shortest rotation taking the measured up onto the world's
    if q is None:  # no usable up (a zero or overflowing mean force): level, with the tilt unknown below
        q = np.array([1.0, 0.0, 0.0, 0.0])
        a = np.array([0.0, 0.0, 9.81])
    heading_var = np.pi**2  # 6D without Earth rate: heading unknown
    slow = np.zeros(kern.S_SIZE)
    slow[kern.S_GRAVITY] = (
        float(np.nanmean(np.linalg.norm(accel[:n], axis=1))) if np.isfinite(accel[:n]).any() else 9.81
    )
    m_first = np.einsum("kij,kj->ki", to_first, mag[:n]) if mag is not None else None
    if setup.use_mag and m_first is not None and np.isfinite(m_first).all(axis=1).any():
        m_w = quat_rotate(q, np.nanmean(m_first, axis=0))
        # rotate about up so that the field's azimuth atan2(m_x, m_y) becomes the declination
        azimuth = np.arctan2(m_w[0], m_w[1])
        q = quat_multiply(quat_from_rotvec([0.0, 0.0, azimuth - setup.declination_rad]), q)
        horizontal = np.hypot(m_w[0], m_w[1])
        slow[kern.S_MAG_NORM] = np.linalg.norm(m_w)
        slow[kern.S_MAG_DIP] = np.arctan2(-m_w[2], horizontal)
        heading_var = params.heading_sigma0**2
    elif setup.latitude_rad is not None:
        found = _gyrocompass_heading(t, gyro, accel, q, setup, params)
        if found is not None:
            q, heading_var = found
    # Motion during the averaging tilts the mean force by up to the samples' spread about it
    spread = float(np.nanmean(np.sum((a_first - a) ** 2, axis=1))) / gravity**2 if np.isfinite(a_first).any() else 0.0
    tilt_var = params.tilt_sigma0**2 + spread
    scale_var = np.where(np.eye(3, dtype=bool), params.scale_factor_sigma**2, params.misalignment_sigma**2)
    acc_var = max(params.accel_gm_sigma / 9.80665, 1e-9) ** 2
    P = np.diag(
        [tilt_var, tilt_var, heading_var]
        + [params.gyro_bias_sigma**2] * 3
        + list(scale_var.ravel())
        + [acc_var, acc_var]
    )
    # The initial tilt makes the mean force point up, so it took in the acceleration of those samples:
    # u = (−δθ_y + δa_x, δθ_x + δa_y) = 0, i.e. δθ_y = δa_x and δθ_x = −δa_y (a prior correlated with the
    # Gauss–Markov acceleration; kept positive definite when the tilt prior is the narrower)
    c = acc_var * min(1.0, np.sqrt(tilt_var / acc_var))
    P[1, kern.X_ACC] = P[kern.X_ACC, 1] = c
    P[0, kern.X_ACC + 1] = P[kern.X_ACC + 1, 0] = -c
    slow[kern.S_T] = t[0] - 1.0 / setup.rate_hz
    g0 = np.nan_to_num(np.asarray(gyro[0], dtype=float))
    slow[kern.S_OMEGA : kern.S_OMEGA + 3] = g0
    slow[kern.S_LP_G : kern.S_LP_G + 3] = g0
    slow[kern.S_LP_A : kern.S_LP_A + 3] = a
    slow[kern.S_GRAV_LP : kern.S_GRAV_LP2 + 3] = np.tile(quat_rotate(q, a), 2)  # the low-passes at rest
    assert q is not None  # quat_rotate just above raises on None
    return InitialState(q=q, b=np.zeros(3), P=P, slow=slow)


def _gyrocompass_heading(
    t: NDArray[np.float64],
    gyro: NDArray[np.float64],
    accel: NDArray[np.float64],
    q_tilt: NDArray[np.float64],
    setup: FilterSetup,
    params: MekfParams,
) -> tuple[NDArray[np.float64], float] | None:
    """North from Earth's rate over the first ``gyrocompass_s`` at rest, when the gyro's expected
    heading error (:func:`gyroemu.sensors.gyrocompass.heading_uncertainty`) is below 20°; else None."""
    from gyroemu.sensors.gyrocompass import gyrocompass, heading_uncertainty

    assert setup.latitude_rad is not None  # the caller's condition
    n = int(np.searchsorted(t, t[0] + params.gyrocompass_s))
    g, a = np.asarray(gyro[:n]), np.asarray(accel[:n])
    ok = np.isfinite(g).all(axis=1) & np.isfinite(a).all(axis=1)
    g, a = g[ok], a[ok]
    if len(g) < 2:
        return None
    duration = float(t[min(n, len(t)) - 1] - t[0]) or 1.0 / setup.rate_hz
    sigma = heading_uncertainty(
        setup.latitude_rad, duration, bias=params.gyro_bias_sigma, noise_density=params.gyro_noise_density
    )
    # at rest: the rate's spread is the white noise alone (3σ), the force's norm is gravity's
    still = (
        np.all(np.std(g, axis=0) < 3 * params.gyro_noise_density * np.sqrt(setup.rate_hz) + 1e-9)
        and np.std(np.linalg.norm(a, axis=1)) < params.rest_accel
    )
    if not (sigma < 20 * _DEG and still):
        return None
    # the data must show Earth's horizontal rate (not, say, a log of zeros): at least half of Ω cos φ
    mean_g, up = g.mean(axis=0), a.mean(axis=0) / np.linalg.norm(a.mean(axis=0))
    if np.linalg.norm(mean_g - (mean_g @ up) * up) < 0.5 * EARTH_RATE * np.cos(setup.latitude_rad):
        return None
    return gyrocompass(g, a).q_ws, sigma**2


class Mekf:
    """The filter (see the module's docstring), obeying :class:`~gyroemu.pipelines.estimation.protocol.AttitudeFilter`.

    Parameters
    ----------
    setup : FilterSetup
        Sample rate, 6D/9D, the device's noise figures, latitude and declination.
    params : MekfParams, optional
        Default: :meth:`MekfParams.for_setup` of ``setup``.

    ``process`` takes rate input; ``process_increments`` takes delta angles (rate-integrating gyros,
    ring lasers). Stamps must increase; a gap is integrated over with the next sample; NaN samples
    are skipped by the measurement they belong to, and a NaN gyro sample holds the last rate.
    """

    name = "mekf"

    def __init__(self, setup: FilterSetup, params: MekfParams | None = None):
        self.setup = setup
        self.params = params if params is not None else MekfParams.for_setup(setup)
        self._p = self.params.vector(setup)
        self._earth = earth_rate_enu(setup)
        self.kf = KalmanFilter(dim_x=kern.X_SIZE, dim_z=2)
        self.q: np.ndarray | None = None
        self.b = np.zeros(3)
        self._slow = np.zeros(kern.S_SIZE)
        self._win = np.zeros(kern.W_SIZE)
        self._phi = np.zeros((3, kern.N_DRIFT))
        self._F = np.eye(kern.X_SIZE)
        self._Q = np.zeros((kern.X_SIZE, kern.X_SIZE))

    @property
    def start_s(self) -> float:
        """Seconds its first block is read for the start (:func:`~.protocol.start_span_s`): ``init_s``
        for the attitude, ``gyrocompass_s`` where it may find north from the Earth's rate (6D, latitude
        known; in 9D only when the field is missing over the first ``init_s``, which this does not hold)."""
        if self.setup.latitude_rad is not None and not self.setup.use_mag:
            return max(self.params.init_s, self.params.gyrocompass_s)
        return self.params.init_s

    def process(self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None = None) -> Estimate:
        """Filter the next block: ``t`` (N,) s, ``gyro`` (N, 3) rad/s, ``accel`` (N, 3) m/s², ``mag``
        (N, 3) T or None. Returns the attitude, bias and attitude covariance after each sample."""
        return self._run(t, np.asarray(gyro, dtype=float), np.empty((0, 3)), accel, mag)

    def process_increments(
        self, t: np.ndarray, delta_angle: np.ndarray, accel: np.ndarray, mag: np.ndarray | None = None
    ) -> Estimate:
        """As :meth:`process`, with the gyro's angle increments over ``[t_{k−1}, t_k]`` (N, 3), rad."""
        delta = np.asarray(delta_angle, dtype=float)
        return self._run(t, delta / np.diff(t, prepend=t[0] - 1 / self.setup.rate_hz)[:, None], delta, accel, mag)

    def _run(
        self,
        t: ArrayLike,
        gyro: NDArray[np.float64],
        delta: NDArray[np.float64],
        accel: ArrayLike,
        mag: ArrayLike | None,
    ) -> Estimate:
        t = np.ascontiguousarray(t, dtype=float)
        accel = np.ascontiguousarray(accel, dtype=float)
        n = len(t)
        mag = (
            np.full((n, 3), np.nan) if mag is None or not self.setup.use_mag else np.ascontiguousarray(mag, dtype=float)
        )
        if self.q is None:
            if n == 0:
                return Estimate(np.empty((0, 4)), np.empty((0, 3)), np.empty((0, 3, 3)))
            init = initial_state(t, gyro, accel, mag, self.setup, self.params)
            self.q, self.b, self._slow = init.q, init.b, init.slow
            self.kf.P = init.P
        if n and not t[0] > self._slow[kern.S_T]:
            raise ValueError(f"stamp {t[0]!r} s does not follow the previous block's {self._slow[kern.S_T]!r} s")
        q_out = np.empty((n, 4))
        b_out = np.empty((n, 3))
        cov_out = np.empty((n, 3, 3))
        k = 0
        kf, p = self.kf, self._p
        while k < n:
            try:
                end = kern.strapdown(
                    self.q,
                    self.b,
                    self._slow,
                    self._win,
                    self._phi,
                    t,
                    gyro,
                    delta,
                    accel,
                    mag,
                    self._earth,
                    p,
                    k,
                    q_out,
                )
            except ValueError:
                bad = k + int(np.argmax(np.diff(np.concatenate([[self._slow[kern.S_T]], t[k:]])) <= 0))
                raise ValueError(f"sample {bad}: stamp {t[bad]!r} s does not increase") from None
            # each sample with the state it was propagated with; a window's end with the window's update
            b_out[k:end] = self.b
            cov_out[k:end] = kf.P[:3, :3]
            if kern.window_due(self._win, p):
                self._window()
                q_out[end - 1] = self.q
                b_out[end - 1] = self.b
                cov_out[end - 1] = kf.P[:3, :3]
            k = end
        return Estimate(q_wb=q_out, gyro_bias=b_out, q_wb_covariance=cov_out)

    @property
    def scale_misalignment(self) -> np.ndarray:
        """The gyro's scale-factor and misalignment errors ``M`` (3, 3) as estimated so far (the rate is
        taken as ``(I − M)(ω_m − b)``); zeros before the first sample."""
        return self._slow[kern.S_SCALE : kern.S_SCALE + 9].reshape(3, 3).copy()

    def _window(self) -> None:
        """The window's prediction and updates, then the injection into the nominal state."""
        kf, p, win, slow = self.kf, self._p, self._win, self._slow
        kern.transition(win, self._phi, self.q, self._earth, p, self._F, self._Q)
        kf.predict(F=self._F, Q=self._Q)
        z, H, R = np.empty(2), np.empty((2, kern.X_SIZE)), np.empty((2, 2))
        if kern.gravity_measurement(win, slow, p, z, H, R):
            kern.gravity_adapt(kf.P, z, H, R, slow, p)
            kern.gravity_update(kf.x.reshape(kern.X_SIZE), kf.P, z, H, R)
        if kern.rest_due(win, slow, p):
            z3, H3, R3 = np.empty(3), np.empty((3, kern.X_SIZE)), np.empty((3, 3))
            kern.rest_measurement(win, self.q, self.b, self._earth, p, z3, H3, R3, kf.P)
            if kern.rest_gate(win, slow, p):
                kf.update(z3.reshape(3, 1), R=R3, H=H3)
        x = kf.x.reshape(kern.X_SIZE)  # a view: the heading update and the injection write through it
        if self.setup.use_mag:
            kern.heading_update(x, kf.P, self.q, win, slow, p)
        kern.inject(x, self.q, self.b, slow, win, self._phi)

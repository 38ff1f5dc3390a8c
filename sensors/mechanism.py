"""The contract between a gyro's mechanism and the IMU around it.

A mechanism (``rate_gyro.py``, ``rate_integrating.py``, ``free_gyro.py``, ``mems.py``, ``fog.py``,
``rlg.py``) models how one kind of gyro turns motion into a physical observable (a gimbal angle, a
pickoff voltage, a Sagnac phase, beat-fringe counts) and what rate or angle that observable implies.
It sees a triad's truth on its own inner time grid, as a :class:`GyroTruth` (sensor axes, SI), and
answers with a :class:`GyroResponse`. The IMU (``imu.py``) then forms the output samples and applies
the standard error terms (``errors.py``) on top.

Noise budget
------------
A mechanism whose physics makes white rate noise (Brownian motion of a MEMS proof mass, shot noise of
a FOG's detector, dither randomisation of an RLG) reports its density through
:meth:`GyroMechanism.intrinsic_noise_density`. The IMU adds only the remainder
``sqrt(N_spec² − N_mech²)`` of the device's specified angle random walk ``N_spec``, so the total
matches the datasheet whichever kind produces it; a mechanism noisier than its specification is a
config error.

Long runs, in chunks
--------------------
An hour at the tens of kilohertz a dithered ring laser needs inside does not fit in memory, so the
IMU feeds long runs to :meth:`GyroMechanism.respond` in consecutive chunks of truth, passing the same
``state`` dict each time: a mechanism reads its initial condition from it (an empty dict means
power-up) and writes its final condition back (gimbal angle and rate, oscillator envelope, Sagnac
loop integrator, beat phase and fringe count, ...). Splitting a run into chunks must not change
its output beyond round-off (random draws come from the same Generator in the same order).
Consecutive chunks share one sample: a chunk's first time is the previous chunk's last, and ``state``
holds the condition at that instant, so the response there repeats the previous chunk's last value.
Cumulative angles restart from 0 at each chunk's first sample.

Output samples
--------------
Output sample ``k`` at time ``t_k`` covers the interval ``[t_{k−1}, t_k]``: the IMU reports the
indicated angle increment over it (or that increment divided by the interval, as a rate). This is
the strapdown convention: a filter that propagates its attitude from ``t_{k−1}`` to ``t_k`` with it
integrates exactly what the gyro saw.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import NDArray

from gyroemu.dynamics.config import Section

__all__ = [
    "GyroTruth",
    "GyroResponse",
    "GyroMechanism",
    "IdealGyro",
    "GYRO_KINDS",
    "mechanism_class",
    "hermite_integral",
]

GYRO_KINDS: dict[str, str] = {
    "ideal": "gyroemu.sensors.mechanism:IdealGyro",
    "rate-gyro": "gyroemu.sensors.rate_gyro:RateGyro",
    "rate-integrating": "gyroemu.sensors.rate_integrating:RateIntegratingGyro",
    "free-gyro": "gyroemu.sensors.free_gyro:FreeGyro",
    "mems": "gyroemu.sensors.mems:MemsGyro",
    "fog": "gyroemu.sensors.fog:FiberOpticGyro",
    "rlg": "gyroemu.sensors.rlg:RingLaserGyro",
}
"""Gyro kind (the ``kind`` key of a device's ``[gyro.mechanism]`` table) → ``"module:Class"``."""


def mechanism_class(kind: str) -> type[GyroMechanism]:
    """The mechanism class of a gyro kind (imported on first use)."""
    module, cls = GYRO_KINDS[kind].split(":")
    mechanism: type[GyroMechanism] = getattr(importlib.import_module(module), cls)
    return mechanism


@dataclass(frozen=True, eq=False)
class GyroTruth:
    """What a triad of gyros is exposed to, on a uniform inner time grid, in the sensor's axes.

    Attributes
    ----------
    t : ndarray (M,)
        Inner sample times, s, uniform with step ``dt``.
    dt : float
        Inner step, s.
    omega : ndarray (M, 3)
        Angular velocity of the sensor relative to inertial space, rad/s.
    alpha : ndarray (M, 3)
        Its time derivative (of the sensor-axes components), rad/s².
    specific_force : ndarray (M, 3) or None
        At the sensor, m/s².
    q_is : ndarray (M, 4) or None
        Attitude of the sensor relative to an inertial frame that coincides with the world frame at
        ``t = 0`` (what a free gyro's rotor holds on to).
    temperature_degC : ndarray (M,) or None
        Sensor temperature, °C.

    The last three are None when the mechanism's :attr:`GyroMechanism.reads` leaves them out: the IMU
    does not interpolate what a mechanism does not read (at tens of kilohertz it would cost more
    than the physics).
    """

    t: NDArray[np.float64]
    dt: float
    omega: NDArray[np.float64]
    alpha: NDArray[np.float64]
    specific_force: NDArray[np.float64] | None = None
    q_is: NDArray[np.float64] | None = None
    temperature_degC: NDArray[np.float64] | None = None

    def __len__(self) -> int:
        return len(self.t)


@dataclass(frozen=True, eq=False)
class GyroResponse:
    """A mechanism's answer on the inner grid of its :class:`GyroTruth`.

    At least one of ``angle`` and ``rate`` is set; where both are, the IMU integrates ``angle`` (a rate
    kind that integrates its own output exactly, like the MEMS baseband model, gives both).

    Attributes
    ----------
    angle : ndarray (M, 3) or None
        Indicated angle about each sensing axis, rad, cumulative from 0 at ``t[0]``: the natural output
        of integrating kinds (rate-integrating gyros, ring lasers counting fringes).
    rate : ndarray (M, 3) or None
        Indicated angular rate, rad/s, at the inner sample times: the natural output of rate kinds.
    raw : dict of str to ndarray
        The physical observables, first axis M (e.g. ``gimbal_angle_rad``, ``sagnac_phase_rad``).
    """

    angle: NDArray[np.float64] | None = None
    rate: NDArray[np.float64] | None = None
    raw: dict[str, NDArray[Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.angle is None and self.rate is None:
            raise ValueError("a GyroResponse has an angle, a rate or both")


class GyroMechanism(Section):
    """Base of every mechanism spec (the ``[gyro.mechanism]`` table of a device file)."""

    kind: str

    reads: ClassVar[frozenset[str]] = frozenset({"specific_force", "q_is", "temperature_degC"})
    """Which of the optional :class:`GyroTruth` fields the mechanism reads (``t``, ``dt``, ``omega``
    and ``alpha`` are always there)."""

    def inner_rate_hz(self, output_rate_hz: float) -> float:
        """The rate the mechanism's physics needs to be simulated at, Hz (at least the output rate)."""
        return output_rate_hz

    def intrinsic_noise_density(self) -> float:
        """White rate noise the physics itself makes, rad/s/√Hz (Allan deviation at 1 s); 0 if none."""
        return 0.0

    def output_angle_quantum(self) -> float | None:
        """Angle of one count of the mechanism's own output counter, rad (one pulse of a counting
        kind); None when its output is not counted. Each sample's rate is then a difference of two
        counts over the interval, which the ``/imu`` covariance charges ``2 (q/T)²/12``."""
        return None

    def rest_bias(self) -> float:
        """Size of the rate the mechanism indicates at rest on the ground (its offsets at the reference
        temperature and its g-sensitivity under 1 g), rad/s; 0 if none. Not part of the device's error
        terms, so a filter that knows only those must still allow for it."""
        return 0.0

    def max_rate(self) -> float:
        """Largest input rate the mechanism indicates unambiguously, rad/s (``inf`` when unbounded).

        A device whose specified range exceeds it cannot work, and is refused.
        """
        return float("inf")

    def respond(self, truth: GyroTruth, rng: np.random.Generator, state: dict[str, Any] | None = None) -> GyroResponse:
        """The mechanism's indicated angle or rate, and its raw observables, for ``truth``.

        ``state``: read the initial condition from it (empty or None: power-up) and write the final
        condition back, so that consecutive chunks continue one run (see the module notes).
        """
        raise NotImplementedError


class IdealGyro(GyroMechanism):
    """A gyro with no mechanism of its own: it indicates the true inertial rate exactly.

    Its angle is the exact integral of the cubic Hermite interpolant of ω (which matches ω and α at
    every inner sample), so an ideal device's increments are exact to fourth order in the step.
    """

    kind: Literal["ideal"] = "ideal"
    reads: ClassVar[frozenset[str]] = frozenset()

    def respond(self, truth: GyroTruth, rng: np.random.Generator, state: dict[str, Any] | None = None) -> GyroResponse:
        return GyroResponse(angle=hermite_integral(truth.omega, truth.alpha, truth.dt))


def hermite_integral(y: NDArray[np.float64], dy: NDArray[np.float64], h: float) -> NDArray[np.float64]:
    """Cumulative integral of the piecewise cubic Hermite interpolant of samples ``y`` with slopes ``dy``.

    On each step ``∫ = h (y_i + y_{i+1})/2 + h² (dy_i − dy_{i+1})/12`` (the corrected trapezoid rule,
    exact for cubics). Returns an array shaped like ``y`` starting at 0.
    """
    steps = 0.5 * h * (y[1:] + y[:-1]) + (h * h / 12.0) * (dy[:-1] - dy[1:])
    out = np.empty_like(y, dtype=float)
    out[0] = 0.0
    np.cumsum(steps, axis=0, out=out[1:])
    return out

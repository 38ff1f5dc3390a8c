"""Truth in windows: where a long run reads its motion a stretch at a time, in bounded memory.

A device measuring a run of hours must not hold the whole truth. It asks a :class:`TruthSource` for
the samples around one stretch of time, ``window(t_lo, t_hi)``, and forgets them when the stretch is
measured. Each window reaches :data:`WINDOW_MARGIN` samples beyond ``[t_lo, t_hi]`` on either side
(fewer at the run's ends), so that the splines a sensor interpolates them with
(:class:`gyroemu.sensors.sampling.SensorTruth`) are those of the whole run to round-off inside the
stretch: a not-a-knot cubic spline's dependence on a sample decays by ``2 − √3 ≈ 0.27`` per sample,
``0.27³² ≈ 2·10⁻¹⁸`` across the margin.

Two sources:

* :class:`SampledTruth` slices a :class:`~gyroemu.dynamics.Trajectory` already in memory (any kind,
  and any trajectory a user builds);
* :class:`ScenarioTruth` reads a scenario whose kind is *pointwise*
  (:attr:`gyroemu.dynamics.scenarios.ScenarioSpec.pointwise`: a closed form in t) segment by segment,
  the segments :meth:`~gyroemu.dynamics.scenarios.Scenario.simulate` is made of, holding two of
  :data:`~gyroemu.dynamics.scenarios.SEGMENT_SAMPLES` samples at most; with ``duration`` None it runs
  without end.

:func:`truth_source` picks the second where the kind allows it and the first otherwise (the kinds that
integrate equations of motion, or that carry a magnetic environment along the path, are simulated
whole).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Protocol

import numpy as np

from .scenarios import segment_bounds, segment_index
from .trajectory import Trajectory, concatenate_trajectories

if TYPE_CHECKING:
    from .scenarios import Scenario

__all__ = [
    "WHOLE_TRUTH_BYTES",
    "WINDOW_MARGIN",
    "TruthSource",
    "SampledTruth",
    "ScenarioTruth",
    "truth_source",
    "simulated_whole",
    "whole_truth_bytes",
]

WHOLE_TRUTH_BYTES = 200
"""Memory a truth sample takes where a run is simulated whole, bytes (measured: README, "Long runs in
bounded memory"; a :class:`~gyroemu.dynamics.Trajectory` holds 23 float64 a sample, 184 bytes, beside
the integrator's own)."""

WINDOW_MARGIN = 32
"""Samples a window reaches beyond the stretch asked for, each side (see the module notes)."""


class TruthSource(Protocol):
    """Where a device reads its truth, a window at a time.

    Attributes
    ----------
    t_start : float
        The first sample's time, s.
    t_end : float or None
        The last sample's time, s; None for a source without end.
    step_s : float
        The interval between samples, s.
    n_samples : int or None
        The number of samples; None for a source without end.
    """

    t_start: float
    t_end: float | None
    step_s: float
    n_samples: int | None

    def window(self, t_lo: float, t_hi: float) -> Trajectory:
        """The samples from :data:`WINDOW_MARGIN` before ``t_lo`` to as many after ``t_hi`` (s), clipped to
        the source's span."""
        ...


class SampledTruth:
    """A :class:`TruthSource` over a trajectory in memory: windows are its slices."""

    def __init__(self, trajectory: Trajectory) -> None:
        if len(trajectory) < 2:
            raise ValueError("a sensor needs a trajectory of at least two samples")
        self.trajectory = trajectory
        self.t_start = float(trajectory.t[0])
        self.t_end: float | None = float(trajectory.t[-1])
        self.step_s = trajectory.duration / (len(trajectory) - 1)
        self.n_samples: int | None = len(trajectory)

    def window(self, t_lo: float, t_hi: float) -> Trajectory:
        t = self.trajectory.t
        lo = max(int(np.searchsorted(t, t_lo, side="right")) - 1 - WINDOW_MARGIN, 0)
        hi = min(int(np.searchsorted(t, t_hi, side="left")) + WINDOW_MARGIN, len(t) - 1)
        return self.trajectory[lo : hi + 1]


class ScenarioTruth:
    """A :class:`TruthSource` reading a pointwise scenario's segments (:meth:`Scenario.segment`) as windows
    need them, holding two at most.

    Parameters
    ----------
    scenario : Scenario
        Its kind must be pointwise (:attr:`gyroemu.dynamics.scenarios.ScenarioSpec.pointwise`).
    duration : float or None
        Seconds of motion; None: without end.
    rate_hz : float or None
        Truth rate; None: the scenario's.

    The samples are those of ``scenario.simulate(duration, rate_hz)``, bit for bit.
    """

    def __init__(self, scenario: Scenario, duration: float | None, rate_hz: float | None = None) -> None:
        if not scenario.spec.pointwise:
            raise ValueError(f"scenario kind {scenario.kind!r} is integrated, not evaluated pointwise")
        self.scenario = scenario
        self.rate_hz = scenario.rate_hz if rate_hz is None else float(rate_hz)
        self.t_start = 0.0
        self.step_s = 1.0 / self.rate_hz
        self.last: int | None = None
        if duration is not None:
            self.last = len(scenario.times(duration, self.rate_hz)) - 1
        self.t_end: float | None = None if self.last is None else self.last / self.rate_hz
        self.n_samples: int | None = None if self.last is None else self.last + 1
        self._segments: dict[int, Trajectory] = {}

    def _segment(self, index: int) -> Trajectory:
        if index not in self._segments:
            for old in [j for j in self._segments if j < index - 1]:
                del self._segments[old]  # windows move forward: the one before is the oldest still needed
            self._segments[index] = self.scenario.segment(index, self.rate_hz, self.last)
        return self._segments[index]

    def window(self, t_lo: float, t_hi: float) -> Trajectory:
        lo = max(math.floor(t_lo * self.rate_hz) - WINDOW_MARGIN, 0)
        hi = math.ceil(t_hi * self.rate_hz) + WINDOW_MARGIN
        if self.last is not None:
            hi = min(hi, self.last)
        first, final = segment_index(lo, self.last), segment_index(hi, self.last)
        parts = []
        for index in range(first, final + 1):
            start, stop = segment_bounds(index, self.last)
            parts.append(self._segment(index)[max(lo, start) - start : min(hi + 1, stop) - start])
        return concatenate_trajectories(parts)


def truth_source(scenario: Scenario, duration: float | None = None, rate_hz: float | None = None) -> TruthSource:
    """The scenario's truth as a :class:`TruthSource`: evaluated window by window where its kind is
    pointwise, otherwise simulated whole. ``duration`` None: the scenario's own (a run without end is
    a :class:`ScenarioTruth` with ``duration`` None)."""
    if not simulated_whole(scenario):
        return ScenarioTruth(scenario, scenario.duration_s if duration is None else duration, rate_hz)
    return SampledTruth(scenario.simulate(duration=duration, rate_hz=rate_hz))


def simulated_whole(scenario: Scenario) -> bool:
    """Whether :func:`truth_source` simulates ``scenario`` whole (a kind that integrates equations of
    motion, or a path through a magnetic environment) rather than reading it in windows."""
    return (
        not scenario.spec.pointwise
        or getattr(getattr(scenario.spec, "site", None), "magnetic_environment", None) is not None
    )


def whole_truth_bytes(scenario: Scenario, duration: float | None = None, rate_hz: float | None = None) -> float:
    """About the memory, bytes, of ``scenario``'s truth over ``duration`` s at ``rate_hz`` (the
    scenario's own where None) held whole: :data:`WHOLE_TRUTH_BYTES` a sample, counted without making the
    time grid (a run of 10⁷ s at 1 kHz would need 80 GB for its times alone)."""
    span = scenario.spec.span_s() if duration is None else float(duration)
    rate = scenario.spec.default_rate_hz() if rate_hz is None else float(rate_hz)
    return (math.floor(span * rate) + 1) * WHOLE_TRUTH_BYTES

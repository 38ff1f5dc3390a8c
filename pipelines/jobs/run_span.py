"""How short a run may be: two truth samples and two of the device's, checked before any work.

A run of ``span`` seconds samples its truth at the scenario's rate, ``round(span · rate) + 1`` samples
(:meth:`gyroemu.dynamics.Scenario.times`), and a sensor needs a trajectory of at least two of them; the
device then needs two samples of its own grid, ``span ≥ 2 / rate``. ``simulate``, ``bench`` and a
campaign file's ``durations_s`` refuse a shorter run with this reason, naming their own argument or key,
instead of failing inside the sensor with a ``ValueError``.
"""

from __future__ import annotations

__all__ = ["short_run_problem"]


def short_run_problem(
    span_s: float, scenario_name: str, truth_rate_hz: float, device_name: str, device_rate_hz: float
) -> str | None:
    """Why a run of ``span_s`` seconds of the scenario (its truth at ``truth_rate_hz``) measured by the
    device (at ``device_rate_hz``) is too short, or None when it is long enough (module notes)."""
    if round(span_s * truth_rate_hz) < 1:
        return (
            f"{span_s:g} s of {scenario_name} at its {truth_rate_hz:g} Hz is one truth sample; the truth needs "
            f"two or more (a step is {1.0 / truth_rate_hz:g} s)"
        )
    if span_s < 2.0 / device_rate_hz:
        return (
            f"{span_s:g} s is shorter than two samples of device {device_name} "
            f"({2.0 / device_rate_hz:g} s at {device_rate_hz:g} Hz)"
        )
    return None

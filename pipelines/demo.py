"""``gyroemu demo``: the main job on built-in defaults, with a short printed summary.

For now it simulates a scenario's truth and summarises it; the sensor, stream and filter stages join
it as they land.
"""

from __future__ import annotations

import time

import numpy as np

from dynamics import load_scenario
from dynamics.rotation import quat_angle

__all__ = ["run_demo"]


def run_demo(scenario: str = "heavy_top", duration: float | None = None) -> int:
    """Simulate ``scenario`` and print what the truth looks like; returns the exit status (0)."""
    s = load_scenario(scenario)
    started = time.perf_counter()
    traj = s.simulate(duration=duration)
    elapsed = time.perf_counter() - started
    rate = np.linalg.norm(traj.omega_b, axis=1)
    force = np.linalg.norm(traj.specific_force_b, axis=1)
    turned = quat_angle(traj.q_wb[-1], traj.q_wb[0])
    print(f"gyroemu demo: scenario '{s.name}' ({s.kind}): {s.description}")
    print(f"  truth: {len(traj)} samples over {traj.duration:g} s at {s.rate_hz:g} Hz, "
          f"simulated in {elapsed:.3f} s ({len(traj) / elapsed / 1e6:.2f} M samples/s)")
    print(f"  |omega_b|          {rate.min():10.4g} .. {rate.max():.4g} rad/s")
    print(f"  |specific_force_b| {force.min():10.4g} .. {force.max():.4g} m/s^2")
    print(f"  attitude change, first to last sample: {np.degrees(turned):.3f} deg")
    print("  more: 'gyroemu scenarios' lists the built-in scenarios; "
          "'gyroemu simulate --scenario NAME --out truth.npz' writes one's truth")
    return 0

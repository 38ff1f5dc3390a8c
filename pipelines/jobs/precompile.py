"""``gyroemu precompile``: compile gyroemu's numba kernels into the user's cache once, ahead of use.

gyroemu compiles its recurrences on first use and caches the machine code per user and per version
(:mod:`gyroemu.dynamics.jit`), so the first runs after an install pay the compiler: up to a minute for
a command that meets many kernels (the attitude filters, the ring laser's dither). This job runs every
built-in scenario, device and filter on a short span, which compiles (or loads) every kernel a
command may meet, so a container image or a CI machine can pay that once, at install time.
"""

from __future__ import annotations

import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np

__all__ = ["PrecompileReport", "run_precompile"]


@dataclass(frozen=True)
class PrecompileReport:
    """What :func:`run_precompile` ran: counts and the wall time, s."""

    scenarios: int
    devices: int
    filters: int
    seconds: float


def run_precompile(out: TextIO = sys.stderr) -> PrecompileReport:
    """Run every built-in scenario, device and filter (online and offline, 9D and 6D) on a short span,
    and a short ``simulate`` → ``estimate`` → ``allan`` round trip through files, so every kernel is in
    the cache. Progress lines go to ``out``."""
    from gyroemu.dynamics import list_scenarios, load_scenario
    from gyroemu.pipelines.estimation.batched import mekf_batch
    from gyroemu.pipelines.estimation.registry import available_filters, make_filter
    from gyroemu.pipelines.estimation.setup import setup_for
    from gyroemu.pipelines.jobs.allan import allan_of_log
    from gyroemu.pipelines.jobs.estimate import estimate_log
    from gyroemu.pipelines.jobs.simulate import SimulateOptions, run_simulate
    from gyroemu.sensors import list_devices

    started = time.perf_counter()
    scenarios = list_scenarios()
    for scenario in scenarios:
        scenario.simulate(duration=min(0.5, scenario.duration_s))
    print(f"precompile: {len(scenarios)} scenarios", file=out, flush=True)

    static = load_scenario("bench_static").simulate(duration=0.2)
    moving = load_scenario("smooth_manoeuvre")
    devices = list_devices()
    for device in devices:
        device.measure(static)
    print(f"precompile: {len(devices)} devices", file=out, flush=True)

    device = next(d for d in devices if d.name == "consumer_mems")
    samples = device.measure(moving.simulate(duration=3.0))
    t = samples.t - samples.t[0]
    names = available_filters(offline=True)
    for use_mag in (True, False):
        setup = setup_for(device, moving, use_mag=use_mag)
        for name in names:
            make_filter(name, setup).process(t, samples.gyro, samples.accel, samples.mag if use_mag else None)
        stacked = np.stack([samples.gyro, samples.gyro]), np.stack([samples.accel, samples.accel])
        mekf_batch(setup, t, *stacked, np.stack([samples.mag, samples.mag]) if use_mag else None)
    print(f"precompile: {len(names)} filters, 9D and 6D", file=out, flush=True)

    with tempfile.TemporaryDirectory(prefix="gyroemu-precompile-") as folder:
        log = Path(folder) / "run.mcap"
        run_simulate(
            SimulateOptions(scenario="bench_static", device="consumer_mems", duration=2.0, out=log, progress=False)
        )
        estimate_log(log, Path(folder) / "estimated.mcap")
        allan_of_log(log)
    seconds = time.perf_counter() - started
    print(f"precompile: done in {seconds:.1f} s", file=out, flush=True)
    return PrecompileReport(len(scenarios), len(devices), len(names), seconds)

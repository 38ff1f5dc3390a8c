"""``gyroemu simulate``: simulate a scenario's truth (and a device's samples of it) and write a file.

Two outputs, by the file's suffix:

- ``.mcap``: a ROS 2 log of the device's samples with their truth
  (:class:`~gyroemu.pipelines.formats.mcap_log.McapLogWriter`); it needs a device. The run goes a block
  at a time (:class:`gyroemu.sensors.device_run.DeviceRun`): the truth is read a window at a time
  (evaluated window by window where the scenario's kind is pointwise,
  :mod:`gyroemu.dynamics.truth_source`), and each block is written on a thread of its own while the
  next is computed (:class:`~gyroemu.pipelines.formats.background_writer.BackgroundWriter`), so memory
  does not grow with the duration. The bytes are those of a run made whole in memory.
- ``.npz``: NumPy arrays (:func:`npz_arrays`): ``truth/<field>`` and ``truth/extras/<name>`` of the
  trajectory and ``scenario_toml``; with a device also ``imu/<field>``, ``raw/<kind>/<observable>``,
  ``device_toml`` and ``seed``. Made in memory and written through a temporary file
  (:func:`write_npz_atomic`).

A bar on stderr shows the samples made (.mcap) or the phases (.npz) when it is a terminal
(:mod:`gyroemu.pipelines.jobs.progress`).
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from gyroemu.dynamics import Scenario
    from gyroemu.dynamics.trajectory import Trajectory
    from gyroemu.sensors import Device
    from gyroemu.sensors.samples import ImuSamples

__all__ = [
    "SimulateError",
    "SimulateOptions",
    "SimulateSummary",
    "check_options",
    "run_simulate",
    "npz_arrays",
    "write_npz_atomic",
]

_TRUTH_FIELDS = ("t", "q_wb", "omega_b", "alpha_b", "specific_force_b", "pos_w", "vel_w", "mag_b")
_IMU_FIELDS = ("t", "t_true", "gyro", "accel", "mag", "temperature_degC", "delta_angle", "delta_velocity")


class SimulateError(ValueError):
    """Bad options of ``gyroemu simulate``, found before any work (the message names the argument)."""


@dataclass(frozen=True)
class SimulateOptions:
    """What ``gyroemu simulate`` simulates, and where it writes it.

    Attributes
    ----------
    scenario : str
        Built-in scenario name or TOML path.
    out : Path
        The file to write: ``.mcap`` (a ROS 2 log; needs ``device``) or ``.npz`` (arrays), in an
        existing folder.
    device : str or None
        Built-in device name or TOML path; None: the truth only.
    duration : float or None
        Seconds to simulate; None: the scenario's.
    rate : float or None
        Output rate of the truth, Hz; None: the scenario's.
    seed : int
        Seed of every random draw of the device.
    progress : bool or None
        Show the phases as a bar on stderr; None: when stderr is a terminal.
    """

    scenario: str
    out: Path
    device: str | None = None
    duration: float | None = None
    rate: float | None = None
    seed: int = 0
    progress: bool | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "out", Path(self.out))


@dataclass(frozen=True)
class SimulateSummary:
    """What a simulate run did.

    Attributes
    ----------
    scenario : str
        The scenario's name.
    truth_samples : int
        Samples of the truth trajectory.
    duration_s : float
        The trajectory's span, seconds.
    device : str or None
        The device's name (None: truth only).
    device_kind : str or None
        The device's gyro kind (``mems``, ``fog``, ...).
    samples : int or None
        The device's samples.
    elapsed_s : float
        Wall-clock seconds of the whole run (simulation, measurement, writing).
    out : Path
        The file written.
    notes : str
        What the scenario reports of its truth (a recorded motion: its smoothing and gaps), or "".
    """

    scenario: str
    truth_samples: int
    duration_s: float
    device: str | None
    device_kind: str | None
    samples: int | None
    elapsed_s: float
    out: Path
    notes: str = ""


def check_options(options: SimulateOptions) -> None:
    """:class:`SimulateError` for an output that cannot be written: a suffix other than .mcap or .npz, a
    missing folder, an .mcap without a device."""
    out = options.out
    if out.suffix not in (".npz", ".mcap"):
        raise SimulateError(f"argument --out: {out}: write a .mcap (ROS 2) or .npz file (got '{out.suffix}')")
    if not out.parent.is_dir():
        raise SimulateError(f"argument --out: {out.parent} is not a folder")
    if out.suffix == ".mcap" and not options.device:
        raise SimulateError(
            "argument --device: an .mcap log holds a device's samples: name a device ('gyroemu presets' lists them)"
        )


def run_simulate(options: SimulateOptions) -> SimulateSummary:
    """Simulate and write ``options.out`` (see the module's notes). Raises :class:`SimulateError` before
    any work for bad options, and ``ConfigError`` for an unknown or bad scenario or device."""
    from gyroemu.dynamics import load_scenario

    check_options(options)
    out = options.out
    scenario = load_scenario(options.scenario)
    device = None
    if options.device:
        from gyroemu.sensors import load_device  # imported where used: it pulls in scipy.signal (0.7 s)

        device = load_device(options.device, seed=options.seed)
    rate = options.rate
    if rate is None and device is not None and scenario.spec.rate_hz is None:
        rate = device.spec.rate_hz  # a recorded motion's truth at the device's own rate
    longest = scenario.spec.max_span_s()
    span = scenario.duration_s if options.duration is None else options.duration
    if longest is not None and span > longest * (1 + 1e-9):
        raise SimulateError(f"argument --duration: {span:g} s is longer than the recording's {longest:.6g} s")
    if device is not None and span < 2.0 / device.spec.rate_hz:
        raise SimulateError(
            f"{scenario.path or scenario.name}: {span:.6g} s of motion is shorter than two samples of "
            f"device {device.name} ({2.0 / device.spec.rate_hz:g} s at {device.spec.rate_hz:g} Hz)"
        )
    started = time.perf_counter()
    samples: int | None
    if out.suffix == ".mcap":
        assert device is not None  # an .mcap needs a device: checked above
        truth_samples, duration_s, samples = _simulate_mcap(options, scenario, device, rate)
    else:
        truth_samples, duration_s, samples = _simulate_npz(options, scenario, device, rate)
    return SimulateSummary(
        scenario=scenario.name,
        truth_samples=truth_samples,
        duration_s=duration_s,
        device=None if device is None else device.name,
        device_kind=None if device is None else device.kind,
        samples=samples,
        elapsed_s=time.perf_counter() - started,
        out=out,
        notes=scenario.spec.report(),
    )


def _simulate_mcap(
    options: SimulateOptions, scenario: Scenario, device: Device, rate: float | None
) -> tuple[int, float, int]:
    """Truth → device → MCAP a block at a time (:class:`gyroemu.sensors.device_run.DeviceRun`), the
    writer on its own thread; returns the truth's sample count and span and the device's sample count."""
    from gyroemu.dynamics.truth_source import truth_source
    from gyroemu.pipelines.formats.background_writer import BackgroundWriter
    from gyroemu.pipelines.formats.mcap_log import McapLogWriter, Recording, truth_pose, truth_series
    from gyroemu.pipelines.jobs.progress import CountProgress
    from gyroemu.sensors.sampling import SensorTruth

    source = truth_source(scenario, options.duration, rate)
    run = device.run(source)
    made = 0
    with CountProgress(run.count, label="simulate", enabled=options.progress) as progress:
        with McapLogWriter(options.out, scenario=scenario) as log, BackgroundWriter(log.write) as writer:
            for block in run:
                body = SensorTruth(block.truth)  # one set of interpolants for both truth channels
                instants = block.samples.t_true if block.samples.t_true is not None else block.samples.t
                q_wb = body.attitude_world(instants)  # the attitude's Slerp, evaluated once for both
                truth = truth_series(block.truth, block.samples, body, q_wb)
                pose = truth_pose(block.truth, block.samples, body, q_wb)
                writer.put(Recording(block.samples, truth=truth, pose=pose, device=device))
                made += len(block.samples)
                progress.advance(len(block.samples))
    assert source.n_samples is not None and source.t_end is not None  # a bounded run
    return source.n_samples, source.t_end - source.t_start, made


def _simulate_npz(
    options: SimulateOptions, scenario: Scenario, device: Device | None, rate: float | None
) -> tuple[int, float, int | None]:
    """Truth (and a device's samples) in memory, written as one .npz."""
    from gyroemu.pipelines.jobs.progress import PhaseProgress

    phases = ["truth", "measure", "write"] if device is not None else ["truth", "write"]
    with PhaseProgress(phases, label="simulate", enabled=options.progress) as progress:
        with progress.phase("truth"):
            traj = scenario.simulate(duration=options.duration, rate_hz=rate)
        samples = None
        if device is not None:
            with progress.phase("measure"):
                samples = device.measure(traj)
        with progress.phase("write"):
            write_npz_atomic(options.out, npz_arrays(scenario, traj, device, samples))
    return len(traj), traj.duration, None if samples is None else len(samples)


def npz_arrays(
    scenario: Scenario, traj: Trajectory, device: Device | None = None, samples: ImuSamples | None = None
) -> dict[str, np.ndarray]:
    """The arrays of an .npz run: ``truth/...``, ``imu/...``, ``raw/<kind>/...`` and the configs
    (``samples``: ``device``'s measurement of ``traj``)."""
    arrays = {f"truth/{name}": getattr(traj, name) for name in _TRUTH_FIELDS}
    arrays.update({f"truth/extras/{k}": v for k, v in traj.extras.items()})
    arrays["scenario_toml"] = np.array(scenario.to_toml())
    if device is not None:
        assert samples is not None, "a device's run needs its samples"
        for name in _IMU_FIELDS:
            if getattr(samples, name) is not None:
                arrays[f"imu/{name}"] = getattr(samples, name)
        for kind, observables in samples.raw.items():
            arrays.update({f"raw/{kind}/{k}": v for k, v in observables.items()})
        arrays["device_toml"] = np.array(device.to_toml())
        arrays["seed"] = np.array(device.seed)
    return arrays


def write_npz_atomic(path: str | os.PathLike, arrays: Mapping[str, Any]) -> None:
    """Write ``arrays`` (name: array-like) to ``path`` (.npz) whole or not at all
    (:func:`gyroemu.pipelines.formats.atomic.write_atomic`)."""
    from gyroemu.pipelines.formats.atomic import write_atomic

    write_atomic(path, lambda f: np.savez(f, **arrays))

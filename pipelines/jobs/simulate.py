"""``gyroemu simulate``: simulate a scenario's truth (and a device's samples of it) and write a file.

Two outputs, by the file's suffix:

- ``.mcap``: a ROS 2 log of the device's samples with their truth
  (:class:`~gyroemu.pipelines.formats.mcap_log.McapLogWriter`); it needs a device. The run goes a block
  at a time (:class:`gyroemu.sensors.device_run.DeviceRun`): the truth is read a window at a time
  (evaluated window by window where the scenario's kind is pointwise,
  :mod:`gyroemu.dynamics.truth_source`), and each block is encoded into its records
  (:meth:`~gyroemu.pipelines.formats.mcap_log.McapLogWriter.prepare`) and written and compressed on a
  thread of its own while the next is computed
  (:class:`~gyroemu.pipelines.formats.background_writer.BackgroundWriter`), so memory does not grow
  with the duration. The bytes are those of a run made whole in memory.
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

from gyroemu.errors import ConfigError
from gyroemu.pipelines.formats.atomic import output_file_problem
from gyroemu.pipelines.jobs.disk_space import (
    MCAP_RECORD_OVERHEAD,
    free_bytes,
    human_size,
    memory_problem,
    whole_truth_problem,
)
from gyroemu.pipelines.jobs.inputs import given_config_files, loaded_files

if TYPE_CHECKING:
    from gyroemu.dynamics import Scenario
    from gyroemu.dynamics.trajectory import Trajectory
    from gyroemu.sensors import Device
    from gyroemu.sensors.samples import ImuSamples

__all__ = [
    "SimulateError",
    "SimulateOptions",
    "SimulateSummary",
    "MAX_DURATION_S",
    "MAX_RATE_HZ",
    "check_options",
    "start_ns",
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
    force : bool
        Overwrite ``out`` if it exists (otherwise :class:`SimulateError`).
    start_time : str, float or None
        The stamp of scenario time 0 in an .mcap log: ISO 8601 or Unix epoch seconds
        (:func:`~gyroemu.pipelines.formats.frames.parse_start_time`); None: the fixed
        :data:`~gyroemu.pipelines.formats.frames.SIMULATE_EPOCH_NS` (2025-01-01T00:00:00Z), so a seed
        gives the same bytes.
    frame_id : str or None
        The IMU's frame in an .mcap log (``/imu``'s ``frame_id``, child of ``base_link`` on
        ``/tf_static``); None: the device's name.
    """

    scenario: str
    out: Path
    device: str | None = None
    duration: float | None = None
    rate: float | None = None
    seed: int = 0
    progress: bool | None = None
    force: bool = False
    start_time: str | float | None = None
    frame_id: str | None = None

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


MAX_DURATION_S = 1e7
"""The longest ``--duration`` :func:`check_options` accepts, seconds (about 116 days): a scenario file's
``duration_s`` limit (``dynamics.scenarios.MAX_DURATION_S``; a test holds them equal: imported from there,
parsing the command line's numbers would load the dynamics, 75 ms)."""

MAX_RATE_HZ = 1e6
"""The highest ``--rate`` :func:`check_options` accepts, Hz: a scenario file's ``rate_hz`` limit too
(``dynamics.scenarios.MAX_RATE_HZ``, held equal by a test)."""

_SEED_LIMIT = 2**128  # numpy's SeedSequence takes integers 0 <= seed < 2**128 here

_TRUTH_NPZ_BYTES = 8 * 23  # float64 t, q_wb (4), omega_b, alpha_b, specific_force_b, pos_w, vel_w, mag_b (3 each)
_IMU_NPZ_BYTES = 8 * 18  # float64 t, t_true, gyro, accel, mag, temperature, delta_angle, delta_velocity


def _check_number(value: float | None, argument: str, unit: str, limit: float) -> None:
    """A finite ``value`` in (0, limit], or None."""
    if value is None:
        return
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise SimulateError(f"argument {argument}: expected a number of {unit}, got {value!r}")
    if not np.isfinite(value):
        raise SimulateError(f"argument {argument}: must be a finite number of {unit}, got {value}")
    if not value > 0:
        raise SimulateError(f"argument {argument}: must be positive, got {value:g}")
    if value > limit:
        raise SimulateError(f"argument {argument}: {value:g} {unit} is more than the limit of {limit:g} {unit}")


def _mcap_bytes_per_sample(device: Device) -> int:
    """Bytes one device sample takes in an .mcap log before compression: its messages (/imu, /mag when
    the device has a magnetometer, /raw/<kind>, /truth/imu, /truth/pose), each with its record overhead."""
    from gyroemu.pipelines.formats.channels import (
        IMU_ROLE,
        MAG_ROLE,
        POSE_ROLE,
        TRUTH_ROLE,
        raw_role,
        role_message_type,
    )

    roles = [IMU_ROLE, TRUTH_ROLE, POSE_ROLE, raw_role(device.kind)]
    if getattr(device.spec, "magnetometer", None) is not None:
        roles.append(MAG_ROLE)
    total = 0
    for role in roles:
        mtype = role_message_type(role)
        if mtype is not None:
            total += mtype.message_size(device.name) + MCAP_RECORD_OVERHEAD
    return total


def _raw_npz_bytes(device: Device) -> int:
    """Bytes of a device sample's raw observables in an .npz (their message's size: an upper bound)."""
    from gyroemu.pipelines.formats.channels import raw_role, role_message_type

    mtype = role_message_type(raw_role(device.kind))
    return 0 if mtype is None else mtype.message_size(device.name)


def _check_size(options: SimulateOptions, scenario: Scenario, device: Device | None) -> None:
    """Refuse a run whose output needs more disk than is free in ``--out``'s folder or, for an .npz
    (made in memory), more memory than the machine has; or whose truth, simulated whole (a kind that
    integrates its motion), needs more memory than the machine has."""
    from gyroemu.dynamics.truth_source import simulated_whole

    span = float(scenario.duration_s if options.duration is None else options.duration)
    device_rate = None if device is None else float(device.spec.rate_hz)
    truth_rate = options.rate or getattr(scenario.spec, "rate_hz", None) or device_rate
    folder = options.out.parent
    free = free_bytes(folder)
    if options.out.suffix == ".mcap":
        assert device is not None and device_rate is not None  # an .mcap needs a device: checked before
        if simulated_whole(scenario):  # its truth is held whole while the log is written block by block
            problem = whole_truth_problem(scenario, options.duration, options.rate)
            if problem is not None:
                raise SimulateError(f"{problem} (a kind that integrates its motion is simulated whole first)")
        samples = span * device_rate + 1
        per = _mcap_bytes_per_sample(device)
        need = samples * per
        what = f"{samples:.4g} samples x {per} bytes"
        change = "shorten --duration"
    else:
        truth = 0.0 if truth_rate is None else span * float(truth_rate) + 1
        need = truth * _TRUTH_NPZ_BYTES
        what = f"{truth:.4g} truth samples x {_TRUTH_NPZ_BYTES} bytes"
        if device is not None and device_rate is not None:
            samples = span * device_rate + 1
            per = _IMU_NPZ_BYTES + _raw_npz_bytes(device)
            need += samples * per
            what += f" + {samples:.4g} device samples x {per} bytes"
        change = "shorten --duration" + (" or lower --rate" if truth_rate is not None else "")
        problem = memory_problem(need, f"{what}; an .npz is made in memory")
        if problem is not None:
            raise SimulateError(
                f"argument --duration: {span:g} s {problem}: {change}, or write an .mcap log "
                "(--out run.mcap, made block by block)"
            )
    if need > free:
        raise SimulateError(
            f"argument --duration: {span:g} s needs about {human_size(need)} of disk ({what}, before compression), "
            f"but {folder} has {human_size(free)} free: {change}, or write to another folder (--out)"
        )


_LAST_STAMP_S = 2.0**31  # builtin_interfaces/Time's int32 seconds: a stamp must lie before 2038-01-19T03:14:08Z


def _check_last_stamp(options: SimulateOptions, span_s: float | None, device: Device | None) -> None:
    """Refuse an .mcap run whose last stamp (``--start-time`` plus the span, the device clock's offset and
    two samples of jitter) lies beyond ROS time's int32 seconds, or whose first (a clock that runs behind
    a start near 1970) before the Unix epoch, which the writer would find only there."""
    if options.out.suffix != ".mcap" or span_s is None:
        return
    start_s = start_ns(options) / 1e9
    if device is not None:
        early = min(float(device.spec.clock.offset_s), 0.0) - 2.0 / float(device.spec.rate_hz)
        if start_s + early < 0:
            raise ConfigError(
                f"an offset of {device.spec.clock.offset_s:g} s puts the run's first stamps before 1970 (the "
                "Unix epoch; log times are unsigned): start later (--start-time) or take the offset in",
                file=device.path or device.name,
                key="clock.offset_s",
            )
    late = 0.0 if device is None else max(float(device.spec.clock.offset_s), 0.0) + 2.0 / float(device.spec.rate_hz)
    if not start_s + float(span_s) + late < _LAST_STAMP_S:
        from gyroemu.pipelines.formats.frames import SIMULATE_EPOCH_NS, format_stamp

        last = format_stamp(int(_LAST_STAMP_S) * 10**9 - 1) + ", the last stamp ROS time's int32 seconds can hold"
        if device is not None and start_s + float(span_s) < _LAST_STAMP_S:  # the device's clock is at fault
            raise ConfigError(
                f"an offset of {device.spec.clock.offset_s:g} s puts the run's stamps after {last}",
                file=device.path or device.name,
                key="clock.offset_s",
            )
        start = format_stamp(SIMULATE_EPOCH_NS) if options.start_time is None else options.start_time
        raise SimulateError(
            f"argument --start-time: {start} plus the {float(span_s):g} s run ends after {last}: start earlier "
            "or shorten --duration"
        )


def check_options(options: SimulateOptions, scenario: Scenario | None = None, device: Device | None = None) -> None:
    """Check ``options`` before any work; raise :class:`SimulateError` naming the argument at fault.

    Parameters
    ----------
    options : SimulateOptions
        What to simulate.
    scenario : Scenario, optional
        The loaded scenario; with it the output's size is checked too.
    device : Device, optional
        The loaded device (with ``scenario``), None for truth only.

    Raises
    ------
    SimulateError
        ``duration`` or ``rate`` not finite and positive or above :data:`MAX_DURATION_S` or
        :data:`MAX_RATE_HZ`; ``seed`` not an integer ``0 <= seed < 2**128``; ``out`` with a suffix other
        than .mcap or .npz, in a missing folder, naming a folder, an existing file without ``force``, or a
        file the run reads (the scenario's or device's file, whatever its suffix, or a recorded motion) even
        with it;
        an .mcap without a device; an .mcap whose last stamp (``start_time`` plus the span) lies beyond
        ROS time's int32 seconds (2038-01-19); and, given ``scenario``, an output that needs more disk than is free
        in ``out``'s folder or (.npz, made in memory) more memory than the machine has.
    """
    _check_number(options.duration, "--duration", "s", MAX_DURATION_S)
    _check_number(options.rate, "--rate", "Hz", MAX_RATE_HZ)
    start_ns(options)
    if options.frame_id is not None:
        from gyroemu.pipelines.formats.frames import check_frame_id

        try:
            check_frame_id(options.frame_id)
        except ValueError as e:
            raise SimulateError(f"argument --frame-id: {e}") from None
    seed = options.seed
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < _SEED_LIMIT:
        raise SimulateError(f"argument --seed: must be an integer from 0 to 2**128 - 1, got {seed!r}")
    out = options.out
    if out.suffix not in (".npz", ".mcap") and not out.is_dir():  # a folder is said to be one, below
        raise SimulateError(f"argument --out: {out}: write a .mcap (ROS 2) or .npz file (got '{out.suffix}')")
    # The inputs: the scenario's and the device's files (whatever their suffix: the resolver reads any
    # path it is given), and once loaded the files they were read from and a recorded motion's file.
    inputs = given_config_files(options.scenario, options.device)
    if scenario is not None:
        inputs += loaded_files(scenario, device)
    problem = output_file_problem(out, force=options.force, inputs=inputs)
    if problem is not None:
        raise SimulateError(f"argument --out: {problem}")
    if out.suffix == ".mcap" and not options.device:
        raise SimulateError(
            "argument --device: an .mcap log holds a device's samples: name a device ('gyroemu presets' lists them)"
        )
    if scenario is None:
        _check_last_stamp(options, options.duration, None)
    else:
        _check_last_stamp(options, scenario.duration_s if options.duration is None else options.duration, device)
        _check_size(options, scenario, device)


def start_ns(options: SimulateOptions) -> int:
    """The stamp of scenario time 0, ns since the Unix epoch (:attr:`SimulateOptions.start_time`);
    :class:`SimulateError` naming ``--start-time`` for a bad one."""
    from gyroemu.pipelines.formats.frames import SIMULATE_EPOCH_NS, parse_start_time

    if options.start_time is None:
        return SIMULATE_EPOCH_NS
    try:
        return parse_start_time(options.start_time)
    except ValueError as e:
        raise SimulateError(str(e)) from None


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
    truth_rate = scenario.rate_hz if rate is None else rate
    if round(span * truth_rate) < 1:  # Scenario.times: round(span · rate) + 1 samples
        argument = "--rate" if options.rate is not None else "--duration" if options.duration is not None else None
        where = f"argument {argument}" if argument else f"{scenario.path or scenario.name}: key 'rate_hz'"
        raise SimulateError(
            f"{where}: {span:g} s at {truth_rate:g} Hz is one truth sample; the truth needs two or more "
            f"(at least {1.0 / span:.3g} Hz over {span:g} s)"
        )
    if device is not None and span < 2.0 / device.spec.rate_hz:
        raise SimulateError(
            f"{scenario.path or scenario.name}: {span:.6g} s of motion is shorter than two samples of "
            f"device {device.name} ({2.0 / device.spec.rate_hz:g} s at {device.spec.rate_hz:g} Hz)"
        )
    check_options(options, scenario, device)  # again, with the output's size
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

    source = truth_source(scenario, options.duration, rate)
    run = device.run(source)
    made = 0
    with CountProgress(run.count, label="simulate", enabled=options.progress) as progress:
        with (
            McapLogWriter(options.out, scenario=scenario, start_ns=start_ns(options)) as log,
            BackgroundWriter(log.write_prepared) as writer,
        ):
            for block in run:
                body = block.interpolants  # the device's own: the splines are built once per block
                instants = block.samples.t_true if block.samples.t_true is not None else block.samples.t
                q_wb = body.attitude_world(instants)  # evaluated once for both truth channels
                truth = truth_series(block.truth, block.samples, body, q_wb)
                pose = truth_pose(block.truth, block.samples, body, q_wb)
                # encoded here, written and compressed on the writer's thread: the two take about as long
                writer.put(
                    log.prepare(
                        Recording(block.samples, truth=truth, pose=pose, device=device, frame_id=options.frame_id)
                    )
                )
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


def write_npz_atomic(path: str | os.PathLike[str], arrays: Mapping[str, Any]) -> None:
    """Write ``arrays`` (name: array-like) to ``path`` (.npz) whole or not at all
    (:func:`gyroemu.pipelines.formats.atomic.write_atomic`)."""
    from gyroemu.pipelines.formats.atomic import write_atomic

    write_atomic(path, lambda f: np.savez(f, **arrays))

"""``gyroemu demo``: the main job on built-in defaults, with a short printed summary.

1. Truth: simulate a scenario (default: the toy heavy top) and summarise it.
2. Sensors: every built-in device measures the same smooth manoeuvre; print each one's gyro error
   against the true mean rate over each sample interval.
3. Gyrocompassing: on a bench at rest, the navigation FOG finds north from Earth's rotation alone;
   the consumer MEMS gyro cannot, and the demo says by how much.
4. Live: a recorder process starts, this process streams the consumer MEMS on the smooth manoeuvre
   over zenoh (peer mode, the default session) paced to its clock while a live MEKF on a session of
   its own filters the stream and publishes its estimate; the recorder writes it all to an MCAP log,
   with the device's config, which the stream announces on ``gyroemu/imu0/config``.
5. Benchmark: every available filter over the recorded log against its truth: the table, the error
   plot, and where the files are. The log carries the device's config, so the filters start from its
   noise figures (as on a simulated log) and the MEKF ranks as in the README's benchmarks.

The demo is an orchestrator: unlike the jobs, which never import one another, it calls them (the
stream, :func:`gyroemu.pipelines.transport.stream.run_stream`, in this process; the recorder as a ``gyroemu
record`` process; the benchmark, :func:`gyroemu.pipelines.jobs.bench.run_bench`).

Its options are checked before any work (:func:`check_options`): the scenario, the durations (at most
:data:`MAX_SECONDS` each: the truth is made in memory, the live stage runs in real time), and ``out``,
which must take files and hold no earlier demo's (``demo.mcap``, the report in ``bench/``) unless ``force``;
none of them may be an input (the scenario's file, a recorded scenario's motion), even with ``force``.

SIGINT or SIGTERM stops the demo at any stage, with status 130 or 143 as any command: the recorder
writes a hidden file beside ``demo.mcap``, moved to that name only once the live stage has run to its
end, so a stop (or a failed live stage) leaves no partial log under the name, and an earlier demo's as
it was.
"""

from __future__ import annotations

import io
import math
import os
import secrets
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from gyroemu.dynamics import ConfigError, load_scenario
from gyroemu.dynamics.rotation import quat_angle
from gyroemu.sensors import list_devices, load_device
from gyroemu.sensors.gyrocompass import gyrocompass, heading_uncertainty
from gyroemu.sensors.sampling import SensorTruth

__all__ = ["DemoError", "MAX_SECONDS", "check_options", "run_demo"]

LOG_NAME = "demo.mcap"
"""The recorded log's name in ``out`` (its benchmark's report goes to ``out/bench``)."""

MAX_SECONDS = 3600.0
"""The longest ``--duration`` and ``--live-seconds`` the demo takes: its truth is simulated in memory and
summarised, and its live stage runs in real time, paced to the clock (then benchmarked); an hour of
either is a long demo. ``gyroemu simulate`` and ``gyroemu stream`` take longer runs."""


class DemoError(ConfigError):
    """Bad options of ``gyroemu demo`` (the message names the argument)."""


def _seconds(value: float | None, argument: str, why: str) -> None:
    if value is None:
        return
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise DemoError(f"argument {argument}: must be a finite positive number of seconds, got {value!r}")
    if value > MAX_SECONDS:
        raise DemoError(f"argument {argument}: {value:g} s is more than the demo's limit of {MAX_SECONDS:g} s: {why}")


def check_options(
    scenario: str = "heavy_top",
    duration: float | None = None,
    out: str | Path = "gyroemu-demo",
    live_seconds: float = 20.0,
    *,
    force: bool = False,
) -> None:
    """:class:`DemoError` naming the argument, before any work: a duration or live time that is not a
    finite positive number of seconds up to :data:`MAX_SECONDS`; an ``out`` that is not a folder or
    cannot take files (read-only, not writable; where it would be made when missing), or holds an earlier
    demo's files (``demo.mcap``, ``bench/bench.md``, ``bench/bench.json``, ``bench/*.png``) and ``force``
    is not given; or where one of those files is an input (the scenario's file, by any path to it, or a
    recorded scenario's motion), even with ``force``. A bad scenario raises its
    :class:`~gyroemu.dynamics.ConfigError` (naming it)."""
    from gyroemu.pipelines.formats.atomic import output_file_problem, output_folder_problem
    from gyroemu.pipelines.jobs.bench import REPORT_FILES, plot_names, report_files_in
    from gyroemu.pipelines.jobs.inputs import loaded_files

    _seconds(duration, "--duration", "the demo makes its truth in memory ('gyroemu simulate' writes longer runs)")
    _seconds(live_seconds, "--live-seconds", "the live stage runs in real time ('gyroemu stream' runs longer)")
    try:
        loaded = load_scenario(scenario)
    except ConfigError as e:
        if e.file is not None:
            raise  # a bad scenario file: names the file and key
        raise DemoError(f"argument --scenario: {e}") from None
    out = Path(out)
    problem = output_folder_problem(out)
    if problem is not None:
        raise DemoError(f"argument --out: {problem}")
    if (out / "bench").exists() and not (out / "bench").is_dir():
        raise DemoError(f"argument --out: {out / 'bench'} is not a folder")
    there = [LOG_NAME] if (out / LOG_NAME).exists() else []
    there += [f"bench/{name}" for name in report_files_in(out / "bench")]
    if there and not force:
        raise DemoError(
            f"argument --out: {out} holds {', '.join(there)} (an earlier demo's?), which the demo would "
            "overwrite (use --force to overwrite them, or another folder)"
        )
    inputs = [Path(scenario), *loaded_files(loaded)]  # a name of no file is no file either
    # the log's report: one case, named after the log (one device), and its plot
    written = [out / LOG_NAME, *(out / "bench" / name for name in (*REPORT_FILES, *plot_names([LOG_NAME])))]
    for path in written:
        if path.parent.is_dir():  # a folder still to be made holds no input
            problem = output_file_problem(path, force=force, inputs=inputs)
            if problem is not None:
                raise DemoError(f"argument --out: {problem}")


def run_demo(
    scenario: str = "heavy_top",
    duration: float | None = None,
    out: str | Path = "gyroemu-demo",
    live_seconds: float = 20.0,
    *,
    force: bool = False,
) -> int:
    """Run the demo and print its summary; returns the exit status: 0, or 130 (SIGINT) or 143 (SIGTERM)
    when its live stage is stopped by a signal (stopped at another stage, ``KeyboardInterrupt`` or the
    caller's exception for SIGTERM goes through). :class:`DemoError` for bad options
    (:func:`check_options`), before any work; ``force``: overwrite an earlier demo's files."""
    check_options(scenario, duration, out, live_seconds, force=force)
    _truth(scenario, duration)
    _sensors()
    _gyrocompass()
    status = _live_and_bench(Path(out), live_seconds)
    if status != 0:
        return status
    print(
        "\nmore: 'gyroemu scenarios' and 'gyroemu presets' list what is built in;\n"
        "      'gyroemu simulate --scenario S --device D --out run.mcap' writes a ROS 2 log, 'gyroemu info run.mcap'\n"
        "      summarises it, 'gyroemu allan run.mcap' fits its noise; 'gyroemu record' and 'gyroemu stream' go live"
    )
    return 0


def _truth(name: str, duration: float | None) -> None:
    s = load_scenario(name)
    started = time.perf_counter()
    traj = s.simulate(duration=duration)
    elapsed = time.perf_counter() - started
    rate = np.linalg.norm(traj.omega_b, axis=1)
    force = np.linalg.norm(traj.specific_force_b, axis=1)
    print(f"gyroemu demo\n\n1. truth: '{s.name}' ({s.kind}): {s.description}")
    print(
        f"   {len(traj)} samples over {traj.duration:g} s at {s.rate_hz:g} Hz, "
        f"simulated in {elapsed:.3f} s ({len(traj) / elapsed / 1e6:.2f} M samples/s)"
    )
    print(
        f"   |omega_b| {rate.min():.4g} .. {rate.max():.4g} rad/s; |specific force| {force.min():.4g} .. "
        f"{force.max():.4g} m/s^2; attitude change {np.degrees(quat_angle(traj.q_wb[-1], traj.q_wb[0])):.3f} deg"
    )


def _sensors(seconds: float = 10.0) -> None:
    traj = load_scenario("smooth_manoeuvre").simulate(duration=seconds)
    print(f"\n2. sensors: every preset measures {seconds:g} s of the smooth manoeuvre (seed 0)")
    print(f"   {'device':<18}{'gyro kind':<18}{'rate Hz':>8}{'gyro rms error deg/s':>22}{'x real time':>13}  note")
    for device in list_devices():
        started = time.perf_counter()
        samples = device.measure(traj)
        elapsed = time.perf_counter() - started
        truth = SensorTruth(traj, device.spec.mounting.q_bs, device.spec.mounting.lever_arm_m)
        instants = np.concatenate([[traj.t[0]], samples.t_true])
        mean = truth.mean_omega(instants)
        error = np.degrees(np.sqrt(np.mean((samples.gyro - mean) ** 2)))
        full_scale = device.gyro_errors.full_scale or device.mechanism.max_rate()
        note = (
            (
                f"saturates: the manoeuvre reaches {np.degrees(np.abs(mean).max()):.0f} deg/s, its range "
                f"{np.degrees(full_scale):.0f}"
            )
            if np.abs(mean).max() > full_scale
            else ""
        )
        print(
            f"   {device.name:<18}{device.kind:<18}{device.spec.rate_hz:>8g}{error:>22.3g}"
            f"{seconds / elapsed:>13.0f}  {note}"
        )
    print(
        "   (error against the true mean rate over each sample interval: bias, scale factor, noise, bandwidth,"
        "\n    quantisation; the ring laser's is its 2.3 arcsec fringe quantum, counted every millisecond)"
    )


def _gyrocompass(seconds: float = 600.0) -> None:
    from gyroemu.dynamics.prescribed import EarthBoundSpec

    scenario = load_scenario("bench_static")
    assert isinstance(scenario.spec, EarthBoundSpec)  # kind "static", at a [site]
    latitude = np.radians(scenario.spec.site.latitude_deg)
    traj = scenario.simulate(duration=seconds)
    north_true = gyrocompass(traj.omega_b, traj.specific_force_b).heading
    print(f"\n3. gyrocompassing: {seconds:g} s at rest on a bench at {scenario.spec.site.latitude_deg:g} deg latitude")
    for name in ("navigation_fog", "consumer_mems"):
        device = load_device(name)
        e, a = device.gyro_errors, device.spec.accelerometer.errors.to_si()
        sigma = heading_uncertainty(
            latitude,
            seconds,
            bias=np.hypot(e.bias[0], e.turn_on_bias[0]),
            noise_density=device.gyro_noise_density[0],
            bias_instability=e.bias_instability[0],
            random_walk=e.random_walk[0],
            accel_bias=np.hypot(a.bias[0], a.turn_on_bias[0]),
        )
        if sigma < np.radians(5.0):
            samples = device.measure(traj)
            found = gyrocompass(samples.gyro, samples.accel)
            error = np.degrees(np.angle(np.exp(1j * (found.heading - north_true))))
            allowed = np.degrees(sigma)
            print(f"   {name}: finds north to {error:+.2f} deg (its noise and bias allow +-{allowed:.2f} deg, 1 sigma)")
        else:
            horizontal = np.degrees(7.292115e-5 * np.cos(latitude)) * 3600
            print(
                f"   {name}: cannot find north: its gyro errors ({sigma * horizontal:.0f} deg/h) "
                f"are {sigma:.0f} times the horizontal Earth rate ({horizontal:.1f} deg/h)"
            )


def _live_and_bench(out: Path, seconds: float) -> int:
    """Stages 4 and 5 (see the module's docstring); the exit status: 0, or 130 (SIGINT) or 143 (SIGTERM)
    when a signal stops the live stage, which leaves no log (and no report)."""
    from gyroemu.pipelines.estimation.metrics import attitude_errors, rmse_deg
    from gyroemu.pipelines.formats.mcap_log import read_mcap
    from gyroemu.pipelines.jobs.bench import LogCase, run_bench
    from gyroemu.pipelines.transport.stream import StreamOptions, run_stream
    from gyroemu.pipelines.transport.zenoh_io import PacingOptions, topic_to_key

    out.mkdir(parents=True, exist_ok=True)
    log = out / LOG_NAME
    partial = out / f".{log.stem}.{secrets.token_hex(6)}.mcap"  # moved to ``log`` once complete
    print(
        f"\n4. live: smooth_manoeuvre through consumer_mems for {seconds:g} s over zenoh (peer mode), "
        "to a recorder process and a live MEKF"
    )
    # only the demo's own device: other gyroemu streams on this machine's zenoh network are not its data
    name = "imu0"
    recorder = subprocess.Popen(
        [sys.executable, "-m", "gyroemu", "record", "--out", str(partial), "--key", topic_to_key(name, "/**")],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        try:
            talk = io.StringIO()
            options = StreamOptions(
                scenario="smooth_manoeuvre",
                device="consumer_mems",
                device_name=name,
                duration=seconds,
                seed=0,
                estimate="mekf",
                pacing=PacingOptions(wait_s=20.0),  # the recorder process starts meanwhile
            )
            status = run_stream(options, out=talk)  # 130 on SIGINT, 143 on SIGTERM
            lines = talk.getvalue().splitlines()
            print("\n".join("   " + line for line in lines if line.startswith("stream: ") and "publishing" not in line))
        finally:
            time.sleep(0.5)
            recorder.send_signal(signal.SIGINT)  # the recorder closes its MCAP (summary, indexes) on SIGINT
            report, _ = recorder.communicate(timeout=30)
        recorded_lines = (line.replace(str(partial), str(log)) for line in report.splitlines())
        print("\n".join("   " + line for line in recorded_lines if line.startswith("record:")))
        if status in (130, 143):  # the stream stopped by SIGINT or SIGTERM: so is the demo
            print("   the live stage was stopped: its recording is removed")
            return status
        if status != 0 or recorder.returncode not in (0, 130):
            print(
                f"   the live stage failed (stream {status}, recorder {recorder.returncode}): its recording is removed"
            )
            return 0
        os.replace(partial, log)
    except BaseException:  # a signal (KeyboardInterrupt, the CLI's SIGTERM) or an error: no recorder left
        if recorder.poll() is None:
            recorder.kill()
            recorder.wait()
        raise
    finally:
        partial.unlink(missing_ok=True)
    recorded = read_mcap(log).device
    if recorded.estimate is not None and recorded.truth is not None:
        # the stream's truth and live MEKF estimate both carry the attitude
        assert recorded.estimate.q_wb is not None and recorded.truth.q_wb is not None
        err = attitude_errors(recorded.estimate.q_wb, recorded.truth.q_wb)
        print(
            f"   live MEKF on the recorded stream: total {rmse_deg(err.total):.2f} deg, inclination "
            f"{rmse_deg(err.inclination):.2f} deg RMSE over {len(err.total)} samples"
        )

    print(f"\n5. benchmark: every available filter over {log.name} against its truth")
    bench = run_bench([LogCase(path=log)], progress=False)
    paths = bench.save(out / "bench")
    print("   " + bench.to_markdown().replace("\n", "\n   "))
    print(f"\n   files: log {log}\n          report {paths['markdown']}, {paths['json']}")
    for png in paths["plots"]:
        print(f"          error plot {png}")
    return 0

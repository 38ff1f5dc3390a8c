"""The ``gyroemu`` command line: a thin layer over the library.

Each subcommand parses its arguments, calls one library function, and prints. Bad usage or bad
input ends with exit status 2 and a message naming the file, key or argument at fault, before any work.
SIGINT ends a command with status 130, SIGTERM with 143, after its clean-up (a partial output removed).
"""

from __future__ import annotations

import argparse
import faulthandler
import json
import math
import os
import signal
import sys
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

from gyroemu.errors import GyroemuError

if TYPE_CHECKING:  # the job modules are imported where used: they pull in numpy, zenoh, ...
    from gyroemu.pipelines.jobs.simulate import SimulateOptions
    from gyroemu.pipelines.transport.foxglove_view import ViewOptions
    from gyroemu.pipelines.transport.record import RecordOptions
    from gyroemu.pipelines.transport.replay import ReplayOptions
    from gyroemu.pipelines.transport.stream import StreamOptions
    from gyroemu.pipelines.transport.zenoh_io import PacingOptions, SessionOptions

__all__ = ["Terminated", "main"]


class UsageError(Exception):
    """A bad command-line argument; the message names it."""


def _cmd_scenarios(args: argparse.Namespace) -> int:
    from gyroemu.dynamics import list_scenarios

    scenarios = list_scenarios()
    if args.json:
        rows = [{"name": s.name, "kind": s.kind, "description": s.description} for s in scenarios]
        print(json.dumps(rows, indent=2))
        return 0
    width = max(len(s.name) for s in scenarios)
    kwidth = max(len(s.kind) for s in scenarios)
    for s in scenarios:
        print(f"{s.name:<{width}}  {s.kind:<{kwidth}}  {s.description}")
    return 0


def _simulate_options(args: argparse.Namespace) -> SimulateOptions:
    from gyroemu.pipelines.jobs.simulate import SimulateOptions

    return SimulateOptions(
        scenario=args.scenario,
        out=Path(args.out),
        device=args.device,
        duration=args.duration,
        rate=args.rate,
        seed=args.seed,
        force=args.force,
        start_time=args.start_time,
        frame_id=args.frame_id,
    )


def _cmd_simulate(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.jobs.simulate import SimulateError, run_simulate

    try:
        summary = run_simulate(_simulate_options(args))
    except SimulateError as e:
        raise UsageError(str(e)) from None
    what = f"{summary.truth_samples} truth samples"
    if summary.samples is not None:
        what += f", {summary.samples} samples of {summary.device} ({summary.device_kind})"
    print(f"{summary.scenario}: {what} over {summary.duration_s:g} s in {summary.elapsed_s:.2f} s -> {summary.out}")
    if summary.notes:
        print(summary.notes)
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.jobs.info import check_plot, log_info

    picture = check_plot(Path(args.log), force=args.force) if args.plot else None  # InfoError before any work
    info = log_info(Path(args.log))
    print(json.dumps(info.to_dict(configs=args.configs), indent=2) if args.json else info.text(configs=args.configs))
    if args.plot:
        from gyroemu.pipelines.jobs.plots import plot_info

        picture = plot_info(Path(args.log), picture)
        print(f"drew {picture}", file=sys.stderr if args.json else sys.stdout)
    return 0


def _mcap_out(text: str) -> Path:
    """``--out`` of a command that writes an MCAP file: a .mcap name (a folder is the job's to refuse,
    with its folder, an input or an existing file: ``formats.atomic.output_file_problem``)."""
    out = Path(text)
    if out.suffix != ".mcap" and not out.is_dir():
        raise UsageError(f"argument --out: {out}: write a .mcap file (got '{out.suffix}')")
    return out


def _cmd_import(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.formats.importers import IMPORTERS, ImportOutputError
    from gyroemu.pipelines.jobs.disk_space import is_disk_full

    source, out = Path(args.file), _mcap_out(args.out)
    started = time.perf_counter()
    try:
        summary = IMPORTERS[args.format](source, out, force=args.force)
    except ImportOutputError as e:
        raise UsageError(f"argument --out: {e}") from None
    except OSError as e:  # reading errors are ImportInputError (a ConfigError); this is the output's write
        if is_disk_full(e):
            raise  # not the argument's fault: main says so, status 1
        raise UsageError(f"argument --out: {out}: {e.strerror or e}") from None
    print(f"{summary} in {time.perf_counter() - started:.2f} s")
    return 0


def _cmd_estimate(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.estimation.registry import FilterError, filter_class
    from gyroemu.pipelines.estimation.setup import FIELD_LAG_FROM_LOG
    from gyroemu.pipelines.jobs.estimate import EstimateError, check_options, estimate_log

    if args.smooth:
        if args.filter not in ("mekf", "mekf-smooth"):
            raise UsageError(f"argument --smooth: smooths the mekf, not --filter {args.filter}")
        args.filter = "mekf-smooth"
    try:
        filter_class(args.filter)
    except FilterError as e:
        raise UsageError(f"argument --filter: {e}") from None
    latencies = _latencies(args)
    source, out = Path(args.file), _mcap_out(args.out)
    started = time.perf_counter()
    try:
        check_options(source, out, force=args.force, plot=args.plot, topic_out=args.topic_out)
        summary = estimate_log(
            source,
            out,
            filter_name=args.filter,
            use_mag=False if args.six_d else None,
            force=args.force,
            topic=args.topic,
            topic_out=args.topic_out,
            latency_s=latencies,
        )
    except EstimateError as e:  # names its argument
        raise UsageError(str(e)) from None
    except GyroemuError:  # a log that cannot be read: its message names the file
        raise
    except ValueError as e:  # a filter refusing the data (e.g. stamps): name the file
        raise UsageError(f"{source}: {e}") from None
    elapsed = time.perf_counter() - started
    picture = None
    if args.plot:
        from gyroemu.pipelines.jobs.plots import plot_estimate

        picture = plot_estimate(out)
    if args.json:
        document = {
            "input": str(source),
            "out": str(out),
            **({"plot": str(picture)} if picture is not None else {}),
            "elapsed_s": elapsed,
            "devices": [
                {"name": name, "samples": n, "filter": flt, "mode": "9D" if nine else "6D"}
                for name, n, flt, nine in summary.devices
            ],
            "topics": [
                {"topic": topic, "topic_out": topic_out, "estimates": count}
                for topic, topic_out, count in summary.topics
            ],
            "field_lags": [
                {
                    "name": name,
                    "lag_ms": lag.lag_s * 1e3,
                    "standard_error_ms": lag.standard_error_s * 1e3 if math.isfinite(lag.standard_error_s) else None,
                    "applied": lag.observable,
                    "mag_latency_ms": mag_latency * 1e3,
                }
                for name, lag, mag_latency in summary.field_lags
            ],
        }
        print(json.dumps(document, indent=2))
        print(f"input copied with its estimate in {elapsed:.2f} s -> {out}", file=sys.stderr)
        return 0
    for name, n, flt, nine in summary.devices:
        print(f"{name}: {n} samples, {flt} ({'9D' if nine else '6D'})")
    for name, lag, _ in summary.field_lags:
        print(f"{name}: {lag.describe()}")
    read = {name for name, _, _ in summary.field_lags}
    for name, _, _, nine in summary.devices:
        if latencies.get("mag") == FIELD_LAG_FROM_LOG and name not in read and not nine:
            print(f"{name}: --latency mag=auto: 6D, no field used: nothing read")
    for topic, topic_out, count in summary.topics:
        print(f"{topic} -> {topic_out}: {count} estimates")
    print(f"input copied with its estimate in {elapsed:.2f} s -> {out}")
    if picture is not None:
        print(f"drew {picture}")
    return 0


def _cmd_precompile(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.jobs.precompile import run_precompile

    run_precompile(out=sys.stderr)
    return 0


def _cmd_presets(args: argparse.Namespace) -> int:
    import numpy as np

    from gyroemu.sensors import list_devices

    devices = list_devices()
    if args.json:
        document = [
            {
                "name": d.name,
                "kind": d.kind,
                "rate_hz": float(d.spec.rate_hz),
                "arw_deg_sqrt_h": float(np.degrees(d.gyro_noise_density.max()) * 60),
                "bias_instability_deg_h": float(np.degrees(d.gyro_errors.bias_instability.max()) * 3600),
                "resembles": d.spec.resembles,
            }
            for d in devices
        ]
        print(json.dumps(document, indent=2))
        return 0
    rows = [("name", "gyro kind", "rate Hz", "ARW deg/sqrt(h)", "bias inst. deg/h", "resembles")]
    for d in devices:
        arw = np.degrees(d.gyro_noise_density.max()) * 60
        instability = np.degrees(d.gyro_errors.bias_instability.max()) * 3600
        rows.append((d.name, d.kind, f"{d.spec.rate_hz:g}", f"{arw:.3g}", f"{instability:.3g}", d.spec.resembles))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip())
    return 0


def _cmd_allan(args: argparse.Namespace) -> int:
    import warnings

    from gyroemu.pipelines.jobs.allan import (
        AllanLogError,
        MotionWarning,
        allan_of_log,
        check_options,
        write_allan_plot,
        write_kalibr_yaml,
    )

    log = Path(args.log)
    out = check_options(log, args.out, args.kalibr, force=args.force, plot=not args.no_plot)  # AllanError first
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", MotionWarning)
        try:
            report = allan_of_log(log, allow_motion=args.allow_motion, topic=args.topic)
        except AllanLogError as e:
            raise UsageError(f"argument LOG: {e}") from None
    for w in caught:
        if issubclass(w.category, MotionWarning):
            print(f"gyroemu allan: warning: {w.message}", file=sys.stderr)
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    if args.json:
        print(report.to_json())
    else:
        print(report.tables())
    done = sys.stderr if args.json else sys.stdout
    if out is not None:
        out = write_allan_plot(report, out, f"Allan deviation: {log.name}")
        print(f"Allan plot -> {out}", file=done)
    if args.kalibr:
        try:
            kalibr = write_kalibr_yaml(report, args.kalibr, force=args.force)
        except ValueError as e:  # no accelerometer fit, or an AllanError saying why the file cannot be written
            raise UsageError(f"argument --kalibr: {e}") from None
        print(f"Kalibr imu.yaml -> {kalibr}", file=done)
    return 0


def _cmd_identify(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.jobs.identify import IdentifyError, IdentifyOptions, run_identify

    rest = []
    for text in args.rest or ():
        try:
            a, b = (float(x) for x in text.split(":"))
        except ValueError:
            raise UsageError(f"argument --rest: expected START:STOP in seconds, got {text!r}") from None
        rest.append((a, b))
    options = IdentifyOptions(
        logs=[Path(p) for p in args.log],
        out=Path(args.out),
        site_out=Path(args.site_out) if args.site_out else None,
        force=args.force,
        rest_intervals=rest or None,
        gravity_m_s2=args.gravity,
        latitude_deg=args.latitude,
    )
    try:
        summary = run_identify(options)
    except IdentifyError as e:
        raise UsageError(e.reason) from None
    gyro = "not found" if summary.gyro_latency_ms is None else f"{summary.gyro_latency_ms:.2f} ms"
    mag = "" if summary.mag_latency_ms is None else f", mag {summary.mag_latency_ms:.2f} ms"
    print(f"{len(summary.logs)} log(s): gyro latency {gyro}{mag} -> {summary.out}")
    if summary.site_out is not None:
        print(f"magnetic environment -> {summary.site_out}")
    for note in summary.notes:
        print(f"note: {note}")
    return 0


def _cmd_campaign(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.campaign import CampaignSpec, SchedulerLostError, campaign_from_spec
    from gyroemu.pipelines.jobs.campaign import CampaignOptions, run_campaign, spec_from_bench_flags

    spec: Path | CampaignSpec
    if args.campaign is not None:
        given = [f for f, v in (("--scenario", args.scenario), ("--device", args.device), ("--log", args.log)) if v]
        given += [f for f, v in (("--filter", args.filter), ("--6d", args.six_d), ("--batched", args.batched)) if v]
        given += ["--latency"] if args.latency else []
        numbers = (("--duration", args.duration), ("--runs", args.runs), ("--seed", args.seed))
        given += [f for f, v in (*numbers, ("--threshold-deg", args.threshold_deg)) if v is not None]
        if given:
            raise UsageError(f"argument --campaign: the campaign file sets the grid; drop {', '.join(given)}")
        spec = Path(args.campaign)
    else:  # --scheduler with today's flags: the grid they describe, as a campaign
        if args.log:
            raise UsageError("argument --scheduler: --log cases run in one process; drop --scheduler")
        if args.latency:
            raise UsageError("argument --latency: times a --log, which runs in one process; drop --scheduler")
        flags = {"scenarios": "--scenario", "devices": "--device", "filters": "--filter", "seed_range": "--seed"}
        try:
            spec = spec_from_bench_flags(
                args.scenario,
                args.device,
                duration=args.duration,
                runs=args.runs,
                seed=args.seed,
                filters=args.filter,
                six_d=args.six_d,
                threshold_deg=args.threshold_deg,
                batched=args.batched,
            )
            campaign_from_spec(spec)  # names checked before any work
        except GyroemuError as e:
            if e.file is not None:
                raise  # a bad scenario or device file: names the file and key
            key = str(getattr(e, "key", "") or "")
            if key == "seed_range":  # the range as a whole: its last seed past what a seed can be
                raise UsageError(
                    f"argument --seed: --seed {args.seed} + --runs {args.runs} must be at most 2**63 (the last "
                    "seed below 2**63: seeds are stored as int64)"
                ) from None
            flag = "--runs" if key == "seed_range.count" else flags.get(key.split("[")[0].split(".")[0], "--scheduler")
            raise UsageError(f"argument {flag}: {e.reason}") from None
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"argument --out: {out} is not a folder")
    options = CampaignOptions(spec=spec, out=out, scheduler=args.scheduler, workers=args.workers, force=args.force)
    try:
        summary = run_campaign(options)
    except SchedulerLostError as e:
        stored = out / "runs"
        hint = f"; the finished tasks are in {stored}: run again to resume" if stored.is_dir() else ""
        print(f"gyroemu bench: error: {e}{hint}", file=sys.stderr)
        return 1
    print(summary.paths["markdown"].read_text(encoding="utf-8"))
    print(
        f"campaign {summary.campaign.name}: {summary.ran} task(s) run, {summary.resumed} found in the store, "
        f"{len(summary.failures)} failed; {summary.rows} rows -> {summary.store}"
    )
    print(f"report -> {summary.paths['markdown']}, {summary.paths['json']}")
    if summary.superseded is not None:
        print(f"note: what {out} held that is not this campaign's (parts, a report) was moved to {summary.superseded}")
    for failure in summary.failures:
        print(f"gyroemu bench: error: {failure.task.cell.label}: {failure.error}", file=sys.stderr)
    return 1 if summary.failures else 0


def _cmd_generate(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.campaign import SchedulerLostError
    from gyroemu.pipelines.jobs.generate import GenerateOptions, run_generate

    out = Path(args.out_dir)
    if out.exists() and not out.is_dir():
        raise UsageError(f"argument --out-dir: {out} is not a folder")
    options = GenerateOptions(spec=Path(args.spec), out_dir=out, scheduler=args.scheduler, workers=args.workers)
    try:
        summary = run_generate(options)
    except SchedulerLostError as e:
        print(f"gyroemu generate: error: {e}; the finished logs are in {out}: run again to resume", file=sys.stderr)
        return 1
    print(
        f"{summary.logs} log(s): {summary.made} made, {summary.resumed} there before, "
        f"{len(summary.failures)} failed, in {summary.elapsed_s:.1f} s -> {summary.index}"
    )
    for failure in summary.failures:
        print(f"gyroemu generate: error: {failure.task.key}: {failure.error}", file=sys.stderr)
    return 1 if summary.failures else 0


_BENCH_NUMBERS = {"duration": 60.0, "runs": 3, "seed": 0, "threshold_deg": 2.0}
"""``bench``'s numbers not given (None: a campaign file refuses them) and their defaults."""


def _cmd_bench(args: argparse.Namespace) -> int:
    import warnings

    # given on the command line (before the defaults fill in): what a bench of logs alone refuses
    simulation_only = [f"--{name}" for name in ("duration", "runs", "seed") if getattr(args, name) is not None]
    simulation_only += ["--batched"] if args.batched else []
    if args.campaign is None:
        for name, default in _BENCH_NUMBERS.items():
            if getattr(args, name) is None:
                setattr(args, name, default)
    if args.campaign is not None or args.scheduler is not None:
        return _cmd_campaign(args)
    if args.workers is not None:  # the local Dask cluster's: a plain bench runs in this process
        raise UsageError("argument --workers: sets the local cluster of --campaign; a plain bench runs in this process")

    from gyroemu.dynamics import ConfigError, load_scenario
    from gyroemu.pipelines.estimation.registry import FilterError, filter_class
    from gyroemu.pipelines.formats.file_names import repeated_file
    from gyroemu.pipelines.jobs.bench import BenchWarning, LogCase, SimCase, check_report_folder, run_bench

    # Names first, so that a typo fails at once and names its argument.
    for spec in args.filter or ():
        try:
            filter_class(spec)
        except FilterError as e:
            raise UsageError(f"argument --filter: {e}") from None
    if args.runs < 1:
        raise UsageError(f"argument --runs: must be at least 1, got {args.runs}")
    simulated = not args.log or args.scenario or args.device
    if not simulated and simulation_only:  # they set the simulated cases' runs: --log alone has none
        raise UsageError(
            f"argument {simulation_only[0]}: sets the simulated cases, and --log without --scenario or --device "
            f"simulates none: drop {', '.join(simulation_only)} (or add a --scenario/--device case)"
        )
    scenarios = args.scenario or ["smooth_manoeuvre"]
    devices = args.device or ["consumer_mems"]
    if simulated:
        from gyroemu.sensors import load_device

        for flag, names, load in (("--scenario", scenarios, load_scenario), ("--device", devices, load_device)):
            for name in dict.fromkeys(names):
                try:
                    load(name)
                except ConfigError as e:
                    if e.file is not None:
                        raise  # a bad file: names the file and key
                    raise UsageError(f"argument {flag}: {e}") from None
    cases: list[SimCase | LogCase] = (
        [
            SimCase(scenario=sc, device=dev, duration=args.duration, six_d=args.six_d)
            for sc in dict.fromkeys(scenarios)
            for dev in dict.fromkeys(devices)
        ]
        if simulated
        else []
    )
    latencies = _latencies(args)
    if latencies and not args.log:
        raise UsageError("argument --latency: times a --log; a simulated device has its own latency_s")
    for log in args.log or ():
        if not Path(log).is_file():
            raise UsageError(f"argument --log: {log}: no such file")
    twice = repeated_file(args.log or ())
    if twice is not None:  # one recording as two cases: a report of the same numbers twice
        first, again = twice
        alias = "" if str(first) == str(again) else f" (as {first})"
        raise UsageError(f"argument --log: {again} is given twice{alias}: give each log once")
    for log in args.log or ():
        cases.append(LogCase(path=log, six_d=args.six_d, latency_s=latencies or None))
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"argument --out: {out} is not a folder")
    check_report_folder(out, force=args.force, cases=cases)  # BenchError before any work
    with warnings.catch_warnings():
        warnings.simplefilter("always", BenchWarning)
        warnings.showwarning = lambda message, category, *a, **k: print(
            f"gyroemu bench: warning: {message}", file=sys.stderr
        )
        try:
            report = run_bench(
                cases,
                filters=args.filter,
                runs=args.runs,
                seed=args.seed,
                threshold_deg=args.threshold_deg,
                batched=args.batched,
            )
        except FilterError as e:
            raise UsageError(f"argument --filter: {e}") from None
    paths = report.save(out, replace_earlier=args.force)
    print(report.to_markdown())
    for png in paths["removed"]:
        print(f"removed {png}: the earlier report's plot of a case this bench does not have")
    print(f"report -> {paths['markdown']}, {paths['json']}")
    for png in paths["plots"]:
        print(f"plot -> {png}")
    return 0


def _cmd_twin(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.jobs.twin import TwinError, TwinOptions, run_twin

    smoothing: dict[str, float] = {}
    for item in args.smoothing or ():
        key, _, value = item.partition("=")
        try:
            smoothing[key] = float(value)
        except ValueError:
            raise UsageError(f"argument --smoothing: expected KEY=NUMBER, got {item!r}") from None
    options = TwinOptions(
        trials=[Path(p) for p in args.trial],
        device=args.device,
        seeds=args.seeds,
        filters=args.filter,
        out=Path(args.out),
        force=args.force,
        workers=args.workers,
        smoothing=smoothing or None,
        **({"site": Path(args.site)} if args.site else {}),
    )
    try:
        report = run_twin(options)
    except TwinError as e:
        raise UsageError(e.reason) from None
    paths = report.save(options.out)
    print(report.to_markdown())
    print(f"report -> {paths['markdown']}, {paths['json']}")
    for png in paths["plots"]:
        print(f"plot -> {png}")
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.jobs.demo import run_demo

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"argument --out: {out} is not a folder")
    return run_demo(
        scenario=args.scenario, duration=args.duration, out=out, live_seconds=args.live_seconds, force=args.force
    )


def _argument_error(error: ValueError, fallback: str) -> Exception:
    """A live command's ``ValueError`` as a usage error: its message names the argument, or else it is
    zenoh's complaint about ``fallback`` (the endpoints). gyroemu's own errors (a bad scenario, device or
    log) name their file already and pass through."""
    if isinstance(error, GyroemuError):
        return error
    text = str(error)
    return UsageError(text if text.startswith("argument") else f"argument {fallback}: {text}")


def _session_options(args: argparse.Namespace) -> SessionOptions:
    """``--connect``, ``--listen``, ``--mode``, ``--config``, and ``--ros2`` with ``--domain`` (default:
    ``ROS_DOMAIN_ID``, else 0), the domain checked before any work. A command without some of these
    flags (the router) leaves them at their defaults."""
    from gyroemu.pipelines.transport.zenoh_io import SessionOptions

    ros2, domain = getattr(args, "ros2", False), getattr(args, "domain", None)
    if not ros2:
        if domain is not None:
            raise UsageError("argument --domain: only with --ros2")
    else:
        from gyroemu.pipelines.formats.ros2_keys import Ros2Error, domain_id

        try:
            domain = domain_id(domain)
        except Ros2Error as e:  # names --domain or ROS_DOMAIN_ID
            raise UsageError(str(e)) from None
    return SessionOptions(
        connect=tuple(args.connect or ()),
        listen=tuple(args.listen or ()),
        mode=getattr(args, "mode", None),
        config_file=None if args.config is None else Path(args.config),
        ros2=ros2,
        domain=domain,
    )


def _pacing_options(args: argparse.Namespace) -> PacingOptions:
    from gyroemu.pipelines.transport.zenoh_io import PacingOptions

    return PacingOptions(wait_s=args.wait)


def _foxglove_options(args: argparse.Namespace) -> ViewOptions | None:
    """``--foxglove`` with ``--foxglove-port`` and ``--foxglove-rate`` (which need it); checked by the job."""
    from gyroemu.pipelines.transport.foxglove_view import DEFAULT_PORT, DEFAULT_RATE_HZ, ViewOptions

    if not args.foxglove:
        for name in ("foxglove_port", "foxglove_rate"):
            if getattr(args, name) is not None:
                raise UsageError(f"argument --{name.replace('_', '-')}: only with --foxglove")
        return None
    port = DEFAULT_PORT if args.foxglove_port is None else args.foxglove_port
    return ViewOptions(port=port, rate_hz=DEFAULT_RATE_HZ if args.foxglove_rate is None else args.foxglove_rate)


def _stream_options(args: argparse.Namespace) -> StreamOptions:
    from gyroemu.pipelines.transport.stream import StreamOptions

    return StreamOptions(
        scenario=args.scenario,
        device=args.device,
        duration=args.duration,
        seed=args.seed,
        device_name=args.device_name,
        estimate=args.estimate,
        as_fast_as_possible=args.as_fast_as_possible,
        start_time=args.start_time,
        session=_session_options(args),
        pacing=_pacing_options(args),
        foxglove=_foxglove_options(args),
        frame_id=args.frame_id,
        **({} if args.tf_rate is None else {"tf_rate_hz": args.tf_rate}),
    )


def _cmd_stream(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.transport.stream import run_stream

    try:
        return run_stream(_stream_options(args))
    except ValueError as e:
        raise _argument_error(e, "--connect/--listen") from None


def _record_options(args: argparse.Namespace) -> RecordOptions:
    from gyroemu.pipelines.transport.record import RecordOptions

    return RecordOptions(
        out_path=Path(args.out),
        duration=args.duration,
        key_expr=args.key,
        report_path=args.report,
        session=_session_options(args),
        force=args.force,
    )


def _cmd_record(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.transport.record import run_record

    options = _record_options(args)
    try:
        return run_record(options)
    except ValueError as e:
        raise _argument_error(e, "--connect/--listen") from None
    except OSError as e:
        raise UsageError(f"argument --out: {options.out_path}: {e.strerror or e}") from None


def _replay_options(args: argparse.Namespace) -> ReplayOptions:
    from gyroemu.pipelines.transport.replay import ReplayOptions

    return ReplayOptions(
        path=Path(args.log),
        rate=args.rate,
        loop=args.loop,
        topics=args.topics,
        device_name=args.device_name,
        session=_session_options(args),
        pacing=_pacing_options(args),
        clock=args.clock,
        foxglove=_foxglove_options(args),
    )


def _cmd_replay(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.transport.replay import run_replay

    try:
        return run_replay(_replay_options(args))
    except ValueError as e:
        raise _argument_error(e, "--connect/--listen") from None


def _cmd_view(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.jobs.view import ViewLogOptions, run_view
    from gyroemu.pipelines.transport.foxglove_view import ViewOptions

    options = ViewLogOptions(
        path=Path(args.log),
        view=ViewOptions(port=args.port, rate_hz=args.rate, host=args.host),
        speed=args.speed,
        playing=not args.paused,
    )
    try:
        return run_view(options)
    except ValueError as e:
        raise _argument_error(e, "--port") from None


def _cmd_router(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.transport.record import run_router

    try:
        return run_router(_session_options(args))
    except ValueError as e:
        raise _argument_error(e, "--listen") from None


def _cmd_completion(args: argparse.Namespace) -> int:
    from gyroemu.pipelines.completion import completion_script

    print(completion_script(build_parser(), args.shell), end="")
    return 0


def _add_zenoh_arguments(p: argparse.ArgumentParser, modes: bool = True) -> None:
    p.add_argument(
        "--connect",
        action="append",
        default=None,
        metavar="ENDPOINT",
        help="zenoh endpoint to connect to, e.g. tcp/host:7447 (repeatable)",
    )
    p.add_argument(
        "--listen",
        action="append",
        default=None,
        metavar="ENDPOINT",
        help="zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable)",
    )
    if modes:
        p.add_argument("--mode", choices=("peer", "client"), default=None, help="zenoh session mode")
    p.add_argument("--config", default=None, metavar="FILE.json5", help="a zenoh JSON5 config file")


def _add_foxglove_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--foxglove",
        action="store_true",
        help="also serve a live 3D view on a Foxglove WebSocket (open ws://localhost:PORT in the Foxglove app; "
        "layout: configs/foxglove/gyroemu.json)",
    )
    p.add_argument("--foxglove-port", type=int, default=None, metavar="PORT", help="its TCP port (default: 8765)")
    p.add_argument(
        "--foxglove-rate", type=_positive, default=None, metavar="HZ", help="its /tf and /scene rate (default: 30)"
    )


def _add_ros2_arguments(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument(
        "--ros2",
        action="store_true",
        help=f"{what} rmw_zenoh's keys <domain>/<topic>/<type>/<RIHS01 hash>, with the liveliness "
        "tokens of a ROS 2 node, for ROS 2 nodes on rmw_zenoh (Jazzy)",
    )
    p.add_argument(
        "--domain", type=int, default=None, metavar="N", help="ROS 2 domain of --ros2 (default: $ROS_DOMAIN_ID, else 0)"
    )


def _add_dask_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="tcp://HOST:8786",
        help="a Dask scheduler to run on (default: a local cluster of one worker process per core)",
    )
    p.add_argument("--workers", type=_count, default=None, metavar="N", help="worker processes of the local cluster")


def _count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got '{text}'") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text}")
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {text}")
    return value


def _duration(text: str) -> float:
    """Seconds: a finite positive number, at most ``MAX_DURATION_S`` (about 116 days)."""
    from gyroemu.pipelines.jobs.simulate import MAX_DURATION_S

    value = _positive(text)
    if value > MAX_DURATION_S:
        raise argparse.ArgumentTypeError(f"{value:g} s is more than the limit of {MAX_DURATION_S:g} s")
    return value


def _add_latency_option(p: argparse.ArgumentParser, whose: str) -> None:
    """``--latency SENSOR=MS`` (repeatable), read by :func:`_latencies`."""
    p.add_argument(
        "--latency",
        type=_latency,
        action="append",
        default=[],
        metavar="SENSOR=MS",
        help=f"how long {whose} gyro or magnetometer lags the motion, ms (repeatable): every filter is fed the field "
        "at the gyro's instant and its attitudes are moved to their stamps (default: a gyroemu log's device's "
        "latency_s, else 0); mag=auto: the gyro's plus the field's lag behind it, read from the log",
    )


def _latencies(args: argparse.Namespace) -> dict[str, float | str]:
    """``--latency``'s sensors and seconds (or ``"auto"``); a sensor given twice is a usage error."""
    latencies: dict[str, float | str] = {}
    for sensor, seconds in args.latency:
        if sensor in latencies:
            raise UsageError(f"argument --latency: {sensor} given twice")
        latencies[sensor] = seconds
    return latencies


def _latency(text: str) -> tuple[str, float | str]:
    """``SENSOR=MS``: a sensor (gyro, mag) and its latency in milliseconds, returned in seconds:
    finite, under a second either way (the devices' ``latency_s`` bound); or ``mag=auto``."""
    from gyroemu.pipelines.estimation.setup import FIELD_LAG_FROM_LOG, LATENCY_SENSORS, check_latency_sensors

    sensor, sep, value_text = text.partition("=")
    sensor = sensor.strip()
    if not sep or sensor not in LATENCY_SENSORS:
        raise argparse.ArgumentTypeError(
            f"expected SENSOR=MS with SENSOR one of {', '.join(LATENCY_SENSORS)}, got {text!r}"
        )
    if value_text.strip() == FIELD_LAG_FROM_LOG:
        try:
            check_latency_sensors({sensor: FIELD_LAG_FROM_LOG})
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
        return sensor, FIELD_LAG_FROM_LOG
    try:
        value = float(value_text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{sensor}: expected a number of milliseconds, got {value_text!r}") from None
    if not (math.isfinite(value) and abs(value) < 1000.0):
        raise argparse.ArgumentTypeError(
            f"{sensor}: must be a finite number of milliseconds under 1000 either way, got {value_text}"
        )
    return sensor, value * 1e-3


def _seed(text: str) -> int:
    """A seed of numpy's generators: an integer 0 <= seed < 2**128."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if not 0 <= value < 2**128:
        raise argparse.ArgumentTypeError(f"must be an integer from 0 to 2**128 - 1, got {text}")
    return value


class _VersionAction(argparse.Action):
    """``--version``: the installed package's version, looked up only when asked for."""

    def __init__(self, option_strings: list[str], dest: str, help: str | None = None) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help=help)

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: object,
        option_string: str | None = None,
    ) -> None:
        import gyroemu

        print(f"gyroemu {gyroemu.__version__}")
        parser.exit(0)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="gyroemu", description="Gyroscope and IMU emulator.")
    parser.add_argument("--version", action=_VersionAction, help="print gyroemu's version and exit")
    loudness = parser.add_mutually_exclusive_group()
    loudness.add_argument("-q", "--quiet", action="store_true", help="print errors only, no warnings")
    loudness.add_argument("-v", "--verbose", action="store_true", help="also print info and debug messages")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("demo", help="run the main job on built-in defaults and print a summary")
    p.add_argument("--scenario", default="heavy_top", help="built-in name or TOML path (default: heavy_top)")
    p.add_argument("--duration", type=_positive, default=None, help="seconds (default: the scenario's)")
    p.add_argument(
        "--live-seconds",
        type=_positive,
        default=20.0,
        help="seconds of the live stream to the recorder and the filter, at most 3600 (default: 20)",
    )
    p.add_argument(
        "--out", default="gyroemu-demo", help="folder for the log, report and plot (default: ./gyroemu-demo)"
    )
    p.add_argument("--force", action="store_true", help="overwrite an earlier demo's log and report in --out")
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser("scenarios", help="list the built-in scenarios, one line each")
    p.add_argument("--json", action="store_true", help="print the list as JSON")
    p.set_defaults(func=_cmd_scenarios)

    p = sub.add_parser("simulate", help="simulate a scenario's truth and write it to a file")
    p.add_argument("--scenario", required=True, help="built-in name or TOML path")
    p.add_argument("--duration", type=_duration, default=None, help="seconds (default: the scenario's)")
    p.add_argument("--rate", type=_positive, default=None, help="output rate, Hz (default: the scenario's)")
    p.add_argument("--device", default=None, help="built-in device name or TOML path (default: truth only)")
    p.add_argument("--seed", type=int, default=0, help="seed of every random draw, 0 to 2**128 - 1 (default: 0)")
    p.add_argument("--out", required=True, help="output file: .mcap (ROS 2 log) or .npz (arrays)")
    p.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    p.add_argument(
        "--start-time",
        default=None,
        help="stamp of scenario time 0 in an .mcap log: ISO 8601 (2025-06-01T12:00:00Z) or Unix epoch seconds "
        "(default: 2025-01-01T00:00:00Z, fixed so a seed gives the same bytes)",
    )
    p.add_argument(
        "--frame-id",
        default=None,
        help="the IMU's tf frame in an .mcap log (/imu's frame_id; default: the device name)",
    )
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser(
        "info",
        help="summarise an MCAP log: devices, topics, counts, rates, gaps, configs",
        description="Summarise an MCAP log: its devices, and per topic the message count, first and last "
        "log time, mean rate (count - 1) / span and gaps (intervals longer than 1.5 times the median).",
    )
    p.add_argument("log", metavar="LOG", help="an MCAP file")
    p.add_argument("--configs", action="store_true", help="also print the embedded scenario and device configs")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--plot", action="store_true", help="draw each IMU topic's series into LOG.info.png")
    p.add_argument("--force", action="store_true", help="overwrite LOG.info.png (--plot) if it exists")
    p.set_defaults(func=_cmd_info)

    p = sub.add_parser(
        "import",
        help="turn another format's recording into an MCAP log (BROAD trials)",
        description="Turn another format's recording into a gyroemu MCAP log. broad: a BROAD trial "
        "(HDF5) to /imu, /mag (tesla), /truth/imu (optical reference, NaN rows kept) "
        "and /movement, stamped t_k = k / sampling_rate from 0.",
    )
    p.add_argument("format", choices=("broad",), help="the input's format")
    p.add_argument("file", metavar="FILE", help="the recording to import (read only), e.g. TRIAL.hdf5")
    p.add_argument("--out", required=True, help="MCAP file to write")
    p.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    p.set_defaults(func=_cmd_import)

    p = sub.add_parser(
        "bench",
        help="benchmark attitude filters on simulated truth and on logs with a truth channel",
        description="Run attitude filters over simulated cases (each --scenario x each --device, Monte Carlo over "
        "--runs device seeds) and over MCAP logs with a /truth/imu channel (--log), and write bench.md, "
        "bench.json and one error plot per case into --out. Reports total, heading and inclination "
        "RMSE (BROAD's definitions), convergence time, gyro-bias error and throughput per filter; "
        "a diverged filter is reported as such. With no arguments: smooth_manoeuvre x consumer_mems, "
        "60 s, 3 runs, every available filter.",
        epilog="Filters: mekf, madgwick, mahony, ahrs-ekf, vqf (needs the vqf package), or your own class as "
        "module:Class or path/to/file.py:Class, made with the FilterSetup and obeying "
        "pipelines/estimation/protocol.py. Offline estimators, run when named and reported in their own "
        "table: mekf-smooth (MEKF + RTS smoother), offline-vqf (vqf.offlineVQF).",
    )
    p.add_argument(
        "--scenario",
        action="append",
        default=None,
        metavar="NAME",
        help="built-in scenario or TOML path (repeatable; default: smooth_manoeuvre unless only --log)",
    )
    p.add_argument(
        "--device",
        action="append",
        default=None,
        metavar="NAME",
        help="built-in device or TOML path (repeatable; default: consumer_mems unless only --log)",
    )
    p.add_argument("--duration", type=_duration, default=None, help="seconds per simulated run (default: 60)")
    p.add_argument("--runs", type=int, default=None, help="Monte Carlo runs per simulated case (default: 3)")
    p.add_argument("--seed", type=_seed, default=None, help="device seed of the first run (default: 0)")
    p.add_argument(
        "--log",
        action="append",
        default=None,
        metavar="FILE.mcap",
        help="an MCAP log with /imu and /truth/imu (repeatable); its /movement mask, if any, "
        "selects the samples that count",
    )
    _add_latency_option(p, "the --log's")
    p.add_argument(
        "--filter",
        action="append",
        default=None,
        metavar="NAME",
        help="a filter to run (repeatable; default: every available online built-in)",
    )
    p.add_argument("--6d", dest="six_d", action="store_true", help="ignore magnetometers (6D: inclination only)")
    p.add_argument(
        "--batched",
        action="store_true",
        help="run the mekf over all runs of a simulated case at once (vectorised across runs)",
    )
    p.add_argument("--threshold-deg", type=_positive, default=None, help="convergence threshold, degrees (default: 2)")
    p.add_argument("--out", default="bench", help="folder for the report (default: ./bench)")
    p.add_argument(
        "--force",
        action="store_true",
        help="overwrite an earlier report in --out (bench.md, bench.json, .png plots); a plain bench first "
        "removes that report's plots of cases it does not have (the plots its bench.json names, no other file)",
    )
    p.add_argument(
        "--campaign",
        default=None,
        metavar="SPEC.toml",
        help="run a campaign file's grid (scenarios x devices x durations x modes x seeds, filters) on Dask; "
        "rows in OUT/runs/*.parquet, resumed when run again",
    )
    _add_dask_arguments(p)
    p.set_defaults(func=_cmd_bench)

    p = sub.add_parser(
        "generate",
        help="write a dataset of MCAP logs over a campaign file's grid, in parallel on Dask",
        description="Write one MCAP log per scenario x device x duration x seed of a campaign file (as "
        "'gyroemu simulate' writes it, byte for byte) and index.parquet / index.csv listing them; "
        "a log already there is kept; any other file in a log's or the index's place is refused, never replaced.",
    )
    p.add_argument("spec", metavar="SPEC.toml", help="the campaign file")
    p.add_argument("--out-dir", required=True, help="folder of the logs and the index (made if missing)")
    _add_dask_arguments(p)
    p.set_defaults(func=_cmd_generate)

    p = sub.add_parser(
        "twin",
        help="compare attitude filters on a recording with truth and on its emulated twins",
        description="Run attitude filters over a recording with truth (a BROAD .hdf5 trial or a gyroemu .mcap "
        "log) and over --seeds twins of it (the recorded motion sensed by --device in the site's modelled "
        "field; twin i of a recording: device, magnetic-environment and handling-offset seeds drawn from i and "
        "the recording's file name), and write twin.md, twin.json and one plot "
        "per recording (residual Allan deviations and spectra at rest, real vs twin) into --out.",
    )
    p.add_argument("trial", nargs="+", metavar="TRIAL", help="a BROAD .hdf5 trial or a .mcap log with /truth/imu")
    p.add_argument("--device", default="aktos_t_broad", help="built-in device or TOML path (default: aktos_t_broad)")
    p.add_argument("--seeds", type=int, default=5, help="twins per recording (default: 5)")
    p.add_argument(
        "--filter", action="append", default=None, metavar="NAME", help="a filter (repeatable; default: all available)"
    )
    p.add_argument("--site", default=None, help="TOML file with a [site] table (default: built-in broad_lab)")
    p.add_argument(
        "--smoothing",
        action="append",
        default=None,
        metavar="KEY=VALUE",
        help="a [smoothing] key of the recorded scenario, e.g. orientation_cutoff_hz=8 (repeatable; default "
        "orientation_cutoff_hz=20 and position_cutoff_hz=10; any key given replaces both defaults)",
    )
    p.add_argument("--workers", type=int, default=2, help="processes for the runs (default: 2)")
    p.add_argument("--out", default="twin", help="folder for the report (default: ./twin)")
    p.add_argument("--force", action="store_true", help="write into an existing non-empty --out folder")
    p.set_defaults(func=_cmd_twin)

    p = sub.add_parser(
        "estimate",
        help="run an attitude filter over an MCAP log and write its /estimate/imu",
        description="Filter an IMU topic of FILE.mcap and write OUT.mcap: every channel of the input copied "
        "unchanged (messages, times, schemas, metadata; /tf and any other topic included) plus the estimate "
        "on --topic-out (default /estimate/imu), one sensor_msgs/msg/Imu message per IMU message at the "
        "same stamps and frame_id (estimated q_wb with its covariance, bias-corrected rate). A file with "
        "several IMU topics needs --topic; a gyroemu log of several devices gets every device filtered, "
        "each to /<device>/estimate/imu. 9D where the device has a magnetometer, unless --6d. A gyroemu log "
        "gives the filter its device's noise figures and the site's latitude, and its estimate is the "
        "body's, in base_link (the sensor's attitude and rate turned by the device's [mounting] q_bs); "
        "other logs use the filter's defaults.",
    )
    p.add_argument("file", metavar="FILE.mcap", help="the log to filter (read only)")
    p.add_argument("--out", required=True, help="MCAP file to write")
    p.add_argument(
        "--force", action="store_true", help="overwrite --out (and with --plot, OUT.estimate.png) if they exist"
    )
    p.add_argument(
        "--filter",
        default="mekf",
        metavar="NAME",
        help="mekf (default), madgwick, mahony, ahrs-ekf, vqf, mekf-smooth, offline-vqf, or module:Class",
    )
    p.add_argument(
        "--smooth",
        action="store_true",
        help="offline: the MEKF forward, then a Rauch-Tung-Striebel smoother backward over the whole log "
        "(the filter mekf-smooth; orientation_covariance is the smoothed one)",
    )
    p.add_argument("--6d", dest="six_d", action="store_true", help="ignore the magnetometer")
    _add_latency_option(p, "the log's")
    p.add_argument(
        "--topic", default=None, metavar="TOPIC", help="the sensor_msgs/msg/Imu topic to filter (needed when several)"
    )
    p.add_argument("--topic-out", default=None, metavar="TOPIC", help="topic of the estimate (default: /estimate/imu)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON (the closing note on stderr)")
    p.add_argument(
        "--plot",
        action="store_true",
        help="draw roll, pitch, yaw against the truth, the attitude error and the bias estimates into OUT.estimate.png",
    )
    p.set_defaults(func=_cmd_estimate)

    p = sub.add_parser("presets", help="list the built-in devices as a table")
    p.add_argument("--json", action="store_true", help="print the list as JSON")
    p.set_defaults(func=_cmd_presets)

    p = sub.add_parser(
        "precompile",
        help="compile every numba kernel into the user's cache now (about 1.5 min once per install), "
        "so that the first runs do not pay the compiler",
    )
    p.set_defaults(func=_cmd_precompile)

    p = sub.add_parser(
        "allan", help="fit the noise terms of a static IMU log and draw its Allan plot (unless --no-plot)"
    )
    p.add_argument("log", metavar="LOG", help="a static gyro log (.mcap, or .npz from 'gyroemu simulate')")
    picture = p.add_mutually_exclusive_group()
    picture.add_argument(
        "--out",
        default=None,
        help="plot to write, in the format its suffix names: .png, .pdf, .svg, ... (default: LOG with .allan.png)",
    )
    picture.add_argument(
        "--no-plot",
        action="store_true",
        help="draw no plot: only the report (and --kalibr); no plot file is written or checked, so a script "
        "may run allan on one log again without --force",
    )
    p.add_argument(
        "--allow-motion", action="store_true", help="analyse a log that is not static (a warning, not an error)"
    )
    p.add_argument(
        "--topic", default=None, metavar="TOPIC", help="the sensor_msgs/msg/Imu topic to analyse (needed when several)"
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON instead of the tables")
    p.add_argument(
        "--kalibr", default=None, metavar="IMU.yaml", help="also write the noise model as Kalibr's/OpenVINS's imu.yaml"
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="overwrite an existing plot (--out, or LOG with .allan.png) or --kalibr file (never LOG itself)",
    )
    p.set_defaults(func=_cmd_allan)

    p = sub.add_parser(
        "identify",
        help="fit a device config (and the site's magnetic environment) to logs with a truth",
        description="Fit a device TOML to recordings with a truth attitude: latencies, gyro bias, scale "
        "factor and misalignment, accelerometer bias, magnetometer hard and soft iron, and noise terms "
        "from the rest phases, each with its uncertainty (in comments); terms the recordings cannot "
        "show are said so and not written. Several logs of one device are pooled.",
    )
    p.add_argument("log", nargs="+", metavar="LOG", help="an .mcap log with /truth/imu, or a BROAD .hdf5 trial")
    p.add_argument("--out", required=True, help="device TOML to write")
    p.add_argument(
        "--site-out",
        default=None,
        help="also write the site: the magnetic environment ([site]) and the handling offset ([handling]), TOML",
    )
    p.add_argument(
        "--rest",
        action="append",
        default=None,
        metavar="START:STOP",
        help="a rest interval in seconds from every log's first sample (repeatable; default: found from the data)",
    )
    p.add_argument("--gravity", type=_positive, default=9.81, help="local gravity, m/s^2, 9.7 to 9.9 (default: 9.81)")
    p.add_argument(
        "--latitude",
        type=float,
        default=None,
        metavar="DEG",
        help="the site's latitude of every log, for the Earth's rate the gyro measures (default: each log's "
        "own site, a gyroemu log's; else unknown, and that log's gyro bias holds the Earth's rate)",
    )
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.set_defaults(func=_cmd_identify)

    zenoh_note = (
        "Without --connect/--listen/--mode/--config, gyroemu processes on one machine find each other "
        "(loopback, tcp/127.0.0.1:7447 plus gossip)."
    )
    p = sub.add_parser(
        "stream", help="simulate a device and publish it live over zenoh, paced to its clock", epilog=zenoh_note
    )
    p.add_argument("--scenario", required=True, help="built-in name or TOML path")
    p.add_argument("--device", required=True, help="built-in device name or TOML path")
    p.add_argument(
        "--start-time",
        default=None,
        help="stamp of the run's time 0: ISO 8601 (2025-06-01T12:00:00Z) or Unix epoch seconds "
        "(default: the wall clock when the stream starts)",
    )
    p.add_argument(
        "--frame-id",
        default=None,
        help="the IMU's tf frame (/imu's frame_id, child of base_link on /tf_static; default: the device name)",
    )
    p.add_argument(
        "--tf-rate",
        type=float,
        default=None,
        help="/tf (map -> base_link, the truth) messages per second, at most (default: 30, a display's rate)",
    )
    p.add_argument(
        "--duration",
        type=_duration,
        default=None,
        help="seconds (default: until SIGINT/SIGTERM for a motion given in closed form; the scenario's own "
        "duration for a recording or a simulated body: heavy-top, free-rigid-body, ship, spacecraft-cmg, drop)",
    )
    p.add_argument("--seed", type=_seed, default=0, help="seed of every random draw (default: 0)")
    p.add_argument("--as-fast-as-possible", action="store_true", help="do not pace to the sample clock")
    p.add_argument("--device-name", default="imu0", help="key expressions gyroemu/<NAME>/... (default: imu0)")
    p.add_argument(
        "--estimate",
        nargs="?",
        const="mekf",
        default=None,
        metavar="FILTER",
        help="also run an attitude filter live on the stream (default filter: mekf) and publish "
        "gyroemu/<NAME>/estimate/imu",
    )
    p.add_argument(
        "--wait",
        type=float,
        default=10.0,
        help="seconds to wait for a subscriber on every key before publishing (default: 10; 0: none)",
    )
    _add_zenoh_arguments(p)
    _add_ros2_arguments(p, "publish on")
    _add_foxglove_arguments(p)
    p.set_defaults(func=_cmd_stream)

    p = sub.add_parser("record", help="record gyroemu zenoh streams into an MCAP file", epilog=zenoh_note)
    p.add_argument("--out", required=True, help="MCAP file to write (written in place)")
    p.add_argument("--force", action="store_true", help="overwrite --out and --report if they exist")
    p.add_argument("--duration", type=_duration, default=None, help="seconds (default: until SIGINT/SIGTERM)")
    p.add_argument(
        "--key", default=None, help="key expression to subscribe to (default: gyroemu/**; with --ros2: <domain>/**)"
    )
    p.add_argument("--report", default=None, metavar="FILE.json", help="also write the sequence report as JSON")
    _add_zenoh_arguments(p)
    _add_ros2_arguments(p, "record from")
    p.set_defaults(func=_cmd_record)

    p = sub.add_parser(
        "replay",
        help="republish an MCAP log over zenoh with its recorded timing",
        epilog="Topics /imu, /<device>/imu, ... go to gyroemu/<device>/...; any other topic /a/b "
        "to gyroemu/<device-name>/a/b. " + zenoh_note,
    )
    p.add_argument("log", metavar="LOG", help="an MCAP file (ROS 2) holding sensor_msgs/msg/Imu messages")
    p.add_argument("--rate", type=_positive, default=1.0, help="speed factor: 2 replays twice as fast (default: 1)")
    p.add_argument(
        "--loop",
        action="store_true",
        help="repeat until SIGINT/SIGTERM (deadlines and header stamps keep increasing)",
    )
    p.add_argument("--topics", nargs="+", default=None, metavar="TOPIC", help="replay only these topics")
    p.add_argument(
        "--clock",
        action="store_true",
        help="also publish rosgraph_msgs/Clock on /clock: the replayed log time, at most 40 Hz "
        "(key gyroemu/<device>/clock; with --ros2 the ROS 2 topic /clock)",
    )
    p.add_argument(
        "--device-name",
        default="imu0",
        help="device of topics the file's gyroemu metadata does not name (default: imu0)",
    )
    p.add_argument(
        "--wait",
        type=float,
        default=10.0,
        help="seconds to wait for a subscriber on every key before publishing (default: 10; 0: none)",
    )
    _add_zenoh_arguments(p)
    _add_ros2_arguments(p, "publish on")
    _add_foxglove_arguments(p)
    p.set_defaults(func=_cmd_replay)

    p = sub.add_parser(
        "view",
        help="serve a log to the Foxglove app (3D view, plots) with play, pause and seek",
        epilog="Open ws://localhost:PORT in the Foxglove app (layout: configs/foxglove/gyroemu.json). "
        "Runs until SIGINT/SIGTERM.",
    )
    p.add_argument("log", metavar="LOG", help="a gyroemu MCAP log")
    p.add_argument("--port", type=int, default=8765, help="TCP port of the Foxglove WebSocket (default: 8765)")
    p.add_argument("--rate", type=_positive, default=30.0, metavar="HZ", help="/tf and /scene rate (default: 30)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default: 127.0.0.1)")
    p.add_argument("--speed", type=_positive, default=1.0, help="initial playback speed (default: 1)")
    p.add_argument("--paused", action="store_true", help="start paused (press play in the app)")
    p.set_defaults(func=_cmd_view)

    p = sub.add_parser("router", help="run a zenoh router (until SIGINT/SIGTERM)")
    p.add_argument(
        "--listen",
        action="append",
        default=None,
        metavar="ENDPOINT",
        help="endpoint to listen on (repeatable; default: tcp/0.0.0.0:7447)",
    )
    p.add_argument(
        "--connect", action="append", default=None, metavar="ENDPOINT", help="other routers to connect to (repeatable)"
    )
    p.add_argument("--config", default=None, metavar="FILE.json5", help="a zenoh JSON5 config file")
    p.set_defaults(func=_cmd_router)

    p = sub.add_parser(
        "completion",
        help="print a shell completion script (bash or zsh)",
        description="Print a completion script for bash or zsh, generated from gyroemu's arguments.",
        epilog="bash: gyroemu completion bash > ~/.local/share/bash-completion/completions/gyroemu; "
        "zsh: gyroemu completion zsh > ~/.zfunc/_gyroemu (a folder in $fpath), or source <(gyroemu completion zsh)",
    )
    p.add_argument("shell", choices=("bash", "zsh"), help="the shell")
    p.set_defaults(func=_cmd_completion)
    return parser


class Terminated(BaseException):
    """SIGTERM, raised in the main thread while :func:`main` runs a command, so that the command's
    clean-up runs (a temporary file removed) as it does for SIGINT's ``KeyboardInterrupt``."""


def _raise_terminated(signum: int, frame: object) -> None:
    raise Terminated()


def _forget_unhandled_interrupt() -> None:
    """Let a caught SIGINT end with :func:`main`'s status 130. CPython notes a ``KeyboardInterrupt``
    that escapes any ``exec`` of a string (scipy's imports run some) as unhandled, and at exit kills
    the process with SIGINT (status -2) even when the exception was caught further up; every ``exec``
    of a string clears that note first (``run_eval_code_obj`` in CPython's pythonrun.c)."""
    exec("None")


def _disk_full_message(error: OSError, args: argparse.Namespace) -> str:
    """What a command stopped by a full disk says: where it was writing (the file the error names, or
    the command's output), that what it wrote through a temporary file is gone, and what to do."""
    where = error.filename or next(
        (getattr(args, name) for name in ("out", "out_dir", "kalibr") if getattr(args, name, None)), None
    )
    place = f" writing {where}" if where is not None else ""
    return (
        f"{error.strerror or error}{place}: stopped; an output written through a temporary file is removed, "
        "a recording keeps what it wrote (its complete chunks read back). Free some space, or write to "
        "another folder"
    )


def main(argv: list[str] | None = None) -> int:
    """Run the ``gyroemu`` command ``argv`` (default: ``sys.argv[1:]``) and return its exit status.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after ``gyroemu``.

    Returns
    -------
    int
        0 on success; 2 for bad usage or bad input (the message names the file, key or argument);
        1 when a disk fills (or a quota runs out) while the command writes: one line on stderr, no
        traceback, the partial output removed; 130 when stopped by SIGINT, 143 by SIGTERM (the partial
        output removed, no traceback).

    Notes
    -----
    While the command runs, warnings and the ``gyroemu`` loggers print one line each on stderr,
    ``gyroemu: warning: <message>`` (:func:`gyroemu.pipelines.log_setup.cli_logging`); the global
    options ``-q`` (errors only) and ``-v`` (info and debug too) set the level.
    """
    from gyroemu.pipelines.log_setup import cli_logging, verbosity_level

    # a crash in native code (numba's kernels, zstd, zenoh) prints every thread's Python stack on stderr
    # rather than nothing (a rare SIGSEGV after SIGINT in CI, 2026-11-26, left no trace to follow)
    if not faulthandler.is_enabled():
        faulthandler.enable()
    parser = build_parser()
    args = parser.parse_args(argv)
    # SIGTERM's default action ends the process without any clean-up: for the command it raises
    # Terminated instead (only the main thread can set handlers; an ignored SIGTERM stays ignored);
    # the previous handler is back after.
    handling = (
        threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGTERM) != signal.SIG_IGN
    )
    previous = signal.signal(signal.SIGTERM, _raise_terminated) if handling else None
    try:
        with cli_logging(verbosity_level(quiet=args.quiet, verbose=args.verbose)):
            status: int = args.func(args)
            return status
    except UsageError as e:
        parser.exit(2, f"gyroemu {args.command}: error: {e}\n")
    except KeyboardInterrupt:
        _forget_unhandled_interrupt()
        return 130
    except Terminated:
        return 143
    except BrokenPipeError:  # the reader went away (`gyroemu info run.mcap | head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except GyroemuError as e:  # bad input (a config, a log): the message names the file and key
        print(f"gyroemu {args.command}: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        from gyroemu.pipelines.jobs.disk_space import is_disk_full

        if not is_disk_full(e):
            raise
        print(f"gyroemu {args.command}: error: {_disk_full_message(e, args)}", file=sys.stderr)
        return 1
    finally:
        if handling:
            signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)


if __name__ == "__main__":
    sys.exit(main())

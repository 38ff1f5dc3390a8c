"""The ``gyroemu`` command line: a thin layer over the library.

Each subcommand parses its arguments, calls one library function, and prints. Bad usage or bad
input ends with exit status 2 and a message naming the file, key or argument at fault.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from dynamics import ConfigError, list_scenarios, load_scenario

__all__ = ["main"]


class UsageError(Exception):
    """A bad command-line argument; the message names it."""


def _cmd_scenarios(args) -> int:
    scenarios = list_scenarios()
    width = max(len(s.name) for s in scenarios)
    kwidth = max(len(s.kind) for s in scenarios)
    for s in scenarios:
        print(f"{s.name:<{width}}  {s.kind:<{kwidth}}  {s.description}")
    return 0


def write_npz_atomic(path: Path, arrays: dict) -> None:
    """Write ``arrays`` to ``path`` (.npz) through a temporary file, so no partial file is left."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent or ".")
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _cmd_simulate(args) -> int:
    out = Path(args.out)
    if out.suffix != ".npz":
        raise UsageError(f"argument --out: {out}: only .npz truth files are written yet (got '{out.suffix}')")
    if not out.parent.is_dir():
        raise UsageError(f"argument --out: {out.parent} is not a folder")
    scenario = load_scenario(args.scenario)
    started = time.perf_counter()
    traj = scenario.simulate(duration=args.duration, rate_hz=args.rate)
    elapsed = time.perf_counter() - started
    arrays = {name: getattr(traj, name) for name in
              ("t", "q_wb", "omega_b", "alpha_b", "specific_force_b", "pos_w", "vel_w", "mag_b")}
    arrays.update({f"extras/{k}": v for k, v in traj.extras.items()})
    arrays["scenario_toml"] = np.array(scenario.to_toml())
    write_npz_atomic(out, arrays)
    print(f"{scenario.name}: {len(traj)} samples over {traj.duration:g} s in {elapsed:.2f} s -> {out}")
    return 0


def _cmd_demo(args) -> int:
    from .demo import run_demo

    return run_demo(scenario=args.scenario, duration=args.duration)


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="gyroemu", description="Gyroscope and IMU emulator.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("demo", help="run the main job on built-in defaults and print a summary")
    p.add_argument("--scenario", default="heavy_top", help="built-in name or TOML path (default: heavy_top)")
    p.add_argument("--duration", type=_positive, default=None, help="seconds (default: the scenario's)")
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser("scenarios", help="list the built-in scenarios, one line each")
    p.set_defaults(func=_cmd_scenarios)

    p = sub.add_parser("simulate", help="simulate a scenario's truth and write it to a file")
    p.add_argument("--scenario", required=True, help="built-in name or TOML path")
    p.add_argument("--duration", type=_positive, default=None, help="seconds (default: the scenario's)")
    p.add_argument("--rate", type=_positive, default=None, help="output rate, Hz (default: the scenario's)")
    p.add_argument("--out", required=True, help="output file (.npz)")
    p.set_defaults(func=_cmd_simulate)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ConfigError as e:
        print(f"gyroemu {args.command}: error: {e}", file=sys.stderr)
        return 2
    except UsageError as e:
        parser.exit(2, f"gyroemu {args.command}: error: {e}\n")
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())

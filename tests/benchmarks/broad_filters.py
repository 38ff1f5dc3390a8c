"""Every available filter on the BROAD trials in ``../shared/datasets/broad`` (``GYROEMU_BROAD_DIR``
overrides): total, heading and inclination RMSE in 9D and inclination RMSE in 6D, per trial and averaged.

    python tests/benchmarks/broad_filters.py [--filter NAME ...] [--trials 02 07 ...] [--mekf-param NAME=VALUE ...]

A script, not a test (the ``ahrs`` filters are per-sample Python: about 3 minutes for all eight trials).
Each filter runs through gyroemu's protocol (the adapters of :mod:`gyroemu.pipelines.estimation.peers` for the
peers) with one global parameter set: its defaults, the sample rate from the file. The errors are the
dataset's own (README of the folder): RMSE in degrees over the ``movement`` samples, NaN reference rows
ignored. The same figures come from ``gyroemu import broad TRIAL.hdf5 --out trial.mcap`` then
``gyroemu bench --log trial.mcap [--6d]``.

``vqf`` is the online filter (:class:`vqf.VQF`, causal, as a live filter must be). ``--offline-vqf`` adds
the rows of ``vqf.offlineVQF`` (acausal: it also filters backwards over the whole trial), called
directly with its defaults, the figures usually quoted for VQF on BROAD; it is not a gyroemu filter.
``--mekf-param accel_tau_s=1.5`` overrides one of :class:`~gyroemu.pipelines.estimation.MekfParams`' defaults for
the ``mekf`` rows (how the defaults' plateau in README was measured).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import fields
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from broad_data import BROAD_DIR, trial_files  # noqa: E402  (tests/benchmarks is the script folder)

from gyroemu.pipelines.estimation.mekf import Mekf, MekfParams  # noqa: E402
from gyroemu.pipelines.estimation.metrics import attitude_errors, rmse_deg  # noqa: E402
from gyroemu.pipelines.estimation.protocol import FilterSetup  # noqa: E402
from gyroemu.pipelines.estimation.registry import available_filters, make_filter, unavailable_filters  # noqa: E402
from gyroemu.pipelines.formats.importers import read_broad  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--filter", action="append", default=None, help="filters (default: every available one)")
    parser.add_argument("--trials", nargs="+", default=None, help="trial numbers, e.g. 02 07 (default: all)")
    parser.add_argument("--offline-vqf", action="store_true", help="also vqf.offlineVQF, called directly")
    parser.add_argument(
        "--mekf-param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="override a MekfParams default for the mekf rows (repeatable)",
    )
    args = parser.parse_args()
    overrides = {}
    for item in args.mekf_param:
        key, _, value = item.partition("=")
        if key not in {f.name for f in fields(MekfParams)} or not value:
            parser.error(f"--mekf-param {item!r}: expected NAME=VALUE with NAME a MekfParams field")
        overrides[key] = float(value)
    files = trial_files(args.trials)
    if not files:
        print(f"no BROAD trials in {BROAD_DIR}", file=sys.stderr)
        return 2
    filters = args.filter or available_filters()
    if args.offline_vqf:
        from vqf import offlineVQF

        filters = filters + ["offlineVQF (direct)"]
    for name, why in unavailable_filters().items():
        print(f"({name} left out: {why})")
    results = {name: [] for name in filters}  # name -> rows (total, heading, inclination, inclination 6D)
    print("| trial | filter | total 9D ° | heading 9D ° | inclination 9D ° | inclination 6D ° |")
    print("|---|---|---|---|---|---|")
    for path in files:
        trial = read_broad(path)
        gyro, accel, mag, ref, movement = trial.gyro, trial.accel, trial.mag_ut, trial.opt_quat, trial.movement
        fs = trial.rate_hz
        t = np.arange(len(gyro)) / fs
        for name in filters:
            if name == "offlineVQF (direct)":
                out = offlineVQF(gyro, accel, mag, 1.0 / fs)
                e9, e6 = attitude_errors(out["quat9D"], ref), attitude_errors(out["quat6D"], ref)
            else:
                make = (
                    (lambda s: Mekf(s, MekfParams.for_setup(s, **overrides)))
                    if name == "mekf" and overrides
                    else (lambda s, name=name: make_filter(name, s))
                )
                e9 = attitude_errors(
                    make(FilterSetup(rate_hz=fs, use_mag=True)).process(t, gyro, accel, mag * 1e-6).q_wb, ref
                )
                e6 = attitude_errors(make(FilterSetup(rate_hz=fs, use_mag=False)).process(t, gyro, accel).q_wb, ref)
            row = (
                rmse_deg(e9.total, movement),
                rmse_deg(e9.heading, movement),
                rmse_deg(e9.inclination, movement),
                rmse_deg(e6.inclination, movement),
            )
            results[name].append(row)
            print(f"| {path.stem[:2]} | {name} | " + " | ".join(f"{x:.2f}" for x in row) + " |", flush=True)
    for name in filters:
        mean = np.mean(results[name], axis=0)
        print(f"| **avg** | {name} | " + " | ".join(f"**{x:.2f}**" for x in mean) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

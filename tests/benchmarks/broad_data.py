"""Where the benchmark scripts find BROAD's trials (``tests/benchmarks`` is the scripts' folder)."""

from __future__ import annotations

import os
from pathlib import Path

BROAD_DIR = Path(
    os.environ.get("GYROEMU_BROAD_DIR", Path(__file__).resolve().parents[3] / "shared" / "datasets" / "broad")
)
"""``$GYROEMU_BROAD_DIR``, else ``shared/datasets/broad`` beside the checkout."""


def trial_files(trials: list[str] | None = None) -> list[Path]:
    """The trials' ``.hdf5`` files in :data:`BROAD_DIR`, sorted; with ``trials`` (numbers such as
    ``"02"``) only those. Empty when none is there."""
    files = sorted(BROAD_DIR.glob("*.hdf5"))
    return [f for f in files if f.name.split("_")[0] in trials] if trials else files

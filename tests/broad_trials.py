"""Where the tests find BROAD's trials: ``../shared/datasets/broad`` beside the project
(``GYROEMU_BROAD_DIR`` overrides), and the skip mark of the tests that need them (CI always has them)."""

import os
from pathlib import Path

import pytest

BROAD_DIR = Path(
    os.environ.get("GYROEMU_BROAD_DIR", Path(__file__).resolve().parents[2] / "shared" / "datasets" / "broad")
)


def needs_trial(name: str | None = None):
    """Skip unless the trial file ``name`` (None: any trial) is in :data:`BROAD_DIR`, saying why."""
    present = (BROAD_DIR / name).is_file() if name else any(BROAD_DIR.glob("*.hdf5"))
    return pytest.mark.skipif(not present, reason=f"BROAD trials not found at {BROAD_DIR} (set GYROEMU_BROAD_DIR)")

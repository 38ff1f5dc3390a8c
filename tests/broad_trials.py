"""Where the tests find BROAD's trials, and what a test that needs them does when they are absent.

The folder is ``$GYROEMU_BROAD_DIR`` when set, otherwise ``shared/datasets/broad`` beside the project's
root (``<root>/../shared/datasets/broad``), wherever the checkout sits. A test that needs a trial skips
and says where it looked; with ``GYROEMU_REQUIRE_DATA=1`` (CI sets it when ``shared/datasets/broad`` lies beside the
checkout) it fails instead, so a moved or missing dataset can never pass as a skip.
"""

import functools
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
BROAD_DIR = Path(os.environ.get("GYROEMU_BROAD_DIR") or ROOT.parent / "shared" / "datasets" / "broad")
REQUIRED = os.environ.get("GYROEMU_REQUIRE_DATA", "") not in ("", "0")


def require_trial(name: str | None = None) -> None:
    """Skip (or, when data are required, fail) unless the trial ``name`` (None: any trial) is present."""
    present = (BROAD_DIR / name).is_file() if name else any(BROAD_DIR.glob("*.hdf5"))
    if present:
        return
    what = name or "any *.hdf5 trial"
    reason = f"BROAD data: {what} not found in {BROAD_DIR} (set GYROEMU_BROAD_DIR to the folder of the trials)"
    if REQUIRED:
        pytest.fail(f"{reason}; GYROEMU_REQUIRE_DATA is set, so this fails instead of skipping", pytrace=False)
    pytest.skip(reason)


def needs_trial(name: str | None = None) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Decorate a test that needs the trial ``name`` (None: any): see :func:`require_trial`."""

    def decorate(test: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(test)
        def run(*args: Any, **kwargs: Any) -> Any:
            require_trial(name)
            return test(*args, **kwargs)

        return run

    return decorate

"""Files written whole or not at all: a temporary file in the target's folder, renamed over the target.

A reader (or a crash) never sees a half-written file at ``path``: the data go to
``.<name>.<random>.tmp`` beside it, which :func:`os.replace` moves to ``path`` once it is complete; on any
error the temporary file is removed and ``path`` is untouched.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

__all__ = ["write_atomic", "write_text_atomic", "write_figure_atomic"]


def write_atomic(path: str | os.PathLike[str], write: Callable[[IO[Any]], object], *, binary: bool = True) -> Path:
    """Call ``write(f)`` on a temporary file opened for writing (bytes, or UTF-8 text with
    ``binary=False``) and move it to ``path``. Returns ``path``."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", encoding="utf-8") as f:
            write(f)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` whole or not at all."""
    return write_atomic(path, lambda f: f.write(text), binary=False)


def write_figure_atomic(fig: Any, path: str | os.PathLike[str], dpi: int) -> Path:
    """Save the matplotlib figure ``fig`` as a PNG at ``path`` whole or not at all, and close it."""
    import matplotlib.pyplot as plt

    try:
        return write_atomic(path, lambda f: fig.savefig(f, dpi=dpi, format="png"))
    finally:
        plt.close(fig)

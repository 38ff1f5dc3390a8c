"""File names: a report's case or trial names turned into safe, distinct stems; inputs given twice."""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from pathlib import Path

__all__ = ["repeated_file", "same_file", "unique_stems"]


def unique_stems(names: list[str]) -> list[str]:
    """One file-name stem per name, in order: characters other than letters, digits, ``.``, ``_`` and ``-``
    become ``_`` (``case`` when nothing is left), and a repeated stem gets ``_2``, ``_3``, ..."""
    stems: list[str] = []
    seen: dict[str, int] = {}
    for name in names:
        stem = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_.") or "case"
        seen[stem] = seen.get(stem, 0) + 1
        stems.append(stem if seen[stem] == 1 else f"{stem}_{seen[stem]}")
    return stems


def same_file(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    """Whether ``a`` and ``b`` name one file: the same resolved path (through symbolic links and ``..``,
    whether it exists or not), or the same existing file (a hard link). An output that is an input is
    refused by this, whatever path names it."""
    a, b = Path(a), Path(b)
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and os.path.samefile(a, b))
    except (OSError, RuntimeError):  # a symbolic link loop
        return False


def repeated_file(paths: Iterable[str | os.PathLike[str]]) -> tuple[Path, Path] | None:
    """The first file of ``paths`` given again, as ``(first, again)`` (the two paths as given; the same
    file by any path to it: a symbolic or hard link, ``./a`` and ``a``), or None when each is given once.
    A path that cannot be read counts by its resolved name."""
    seen: dict[object, Path] = {}
    for path in map(Path, paths):
        try:
            st = os.stat(path)
            key: object = (st.st_dev, st.st_ino)
        except OSError:
            key = path.resolve()
        if key in seen:
            return seen[key], path
        seen[key] = path
    return None

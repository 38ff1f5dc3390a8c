"""File names made from free text: a report's case or trial names turned into safe, distinct stems."""

from __future__ import annotations

import re

__all__ = ["unique_stems"]


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

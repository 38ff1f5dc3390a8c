"""A full disk at the n-th file a job writes through a temporary file
(:mod:`gyroemu.pipelines.formats.atomic`), without filling a real one."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest


def disk_full_at(monkeypatch: pytest.MonkeyPatch, n: int) -> list[str]:
    """Make the ``n``-th file written through a temporary file (from 1) meet a full disk
    (``OSError(ENOSPC)``) after part of its data; returns the names of the files asked for, in order."""
    from gyroemu.pipelines.formats import atomic

    real = atomic.StagedFiles.write
    asked: list[str] = []

    def write(self, path, write, *, binary=True):
        asked.append(Path(path).name)
        if len(asked) != n:
            return real(self, path, write, binary=binary)

        def part_then_full(f) -> None:
            f.write(b"part" if binary else "part")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        return real(self, path, part_then_full, binary=binary)

    monkeypatch.setattr(atomic.StagedFiles, "write", write)
    return asked


def contents(folder: Path) -> dict[str, bytes]:
    """The plain files in ``folder`` by name, with their bytes (a folder in it as ``b"<folder>"``)."""
    return {p.name: b"<folder>" if p.is_dir() else p.read_bytes() for p in sorted(folder.iterdir())}

"""A folder of Parquet part files, one per finished task, written whole or not at all.

Each finished task's rows go to ``<folder>/part-<key>.parquet`` through a temporary file in the same
folder and a rename (:func:`gyroemu.pipelines.formats.atomic.write_atomic`), so a part is either
complete or absent: a campaign stopped at any instant and started again runs exactly the tasks whose
part is missing, and no row is stored twice. The temporary files' names start with a dot, which
Parquet readers skip, so the folder reads as one table at any time::

    pyarrow.dataset.dataset("bench/runs").to_table()       # or pandas.read_parquet("bench/runs")

Each part is synced to the disk before its rename (:mod:`gyroemu.pipelines.formats.atomic`), so a power
loss leaves it whole or absent. A part that is there but no whole Parquet file (empty, cut short: left so
by a store written before parts were synced, or by a failing disk) counts as missing, with a
:class:`StoreWarning`: its task runs again and its new part replaces it (:meth:`PartStore.missing`); one
that looks whole but cannot be read is left out of :meth:`PartStore.read`, with a warning.

pyarrow is imported when a part is written or read, not with this module.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterable
from pathlib import Path
from typing import Any

__all__ = ["PartStore", "StoreWarning", "arrow_schema", "readable"]

_MAGIC = b"PAR1"
"""What a Parquet file starts and ends with."""


class StoreWarning(UserWarning):
    """A part of the store that cannot be read: its task runs again, or its rows are left out."""


def arrow_schema(columns: dict[str, str]) -> Any:
    """A ``pyarrow.Schema`` of ``{column: pyarrow type name}`` (``"float64"``, ``"string"``, ``"bool_"``, ...)."""
    import pyarrow as pa

    return pa.schema([(name, getattr(pa, kind)()) for name, kind in columns.items()])


def readable(path: Path) -> Path:
    """Give ``path`` (a temporary file's 0600 after a rename) the mode a new file gets here: 0666 minus
    the umask, so that the other users of a shared folder (a cluster's) can read it. Returns ``path``."""
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(path, 0o666 & ~mask)
    return path


class PartStore:
    """Parquet parts keyed by task in ``folder`` (made when first written)."""

    PREFIX = "part-"
    SUFFIX = ".parquet"

    def __init__(self, folder: str | Path, schema: Any = None) -> None:
        self.folder = Path(folder)
        self.schema = schema  # a pyarrow.Schema the rows are cast to, or None: inferred

    def path(self, key: str) -> Path:
        """The part file of task ``key``."""
        return self.folder / f"{self.PREFIX}{key}{self.SUFFIX}"

    def has(self, key: str) -> bool:
        """Whether task ``key``'s part is stored."""
        return self.path(key).is_file()

    def keys(self) -> set[str]:
        """The keys of every stored part."""
        if not self.folder.is_dir():
            return set()
        n = len(self.PREFIX)
        return {p.name[n : -len(self.SUFFIX)] for p in self.folder.glob(f"{self.PREFIX}*{self.SUFFIX}")}

    def damaged(self, key: str) -> str | None:
        """Why task ``key``'s part (there) is no whole Parquet file (``"empty"``, ``"cut short, or not
        Parquet"``, an error reading it), or None
        when it looks whole: its size and the ``PAR1`` at both ends, a few bytes read, not its rows."""
        try:
            with open(self.path(key), "rb") as f:
                size = os.fstat(f.fileno()).st_size
                if size == 0:
                    return "empty"
                head = f.read(len(_MAGIC))
                f.seek(max(0, size - len(_MAGIC)))
                tail = f.read(len(_MAGIC))
        except OSError as exc:
            return exc.strerror or type(exc).__name__
        if size < 3 * len(_MAGIC) or head != _MAGIC or tail != _MAGIC:
            return "cut short, or not Parquet"
        return None

    def missing(self, keys: Iterable[str]) -> set[str]:
        """Of ``keys``, those whose task has to run: no part, or a damaged one (:meth:`damaged`; a
        :class:`StoreWarning` says so, and the new part replaces it)."""
        out = set()
        for key in dict.fromkeys(keys):
            if not self.has(key):
                out.add(key)
                continue
            why = self.damaged(key)
            if why is not None:
                warnings.warn(f"{self.path(key)}: {why}: its task runs again", StoreWarning, stacklevel=2)
                out.add(key)
        return out

    def temporaries(self, keys: Iterable[str]) -> list[Path]:
        """The temporary files of the parts ``keys`` that a write stopped mid-way (a killed process)
        left in the folder (:func:`~gyroemu.pipelines.formats.atomic.temporaries`)."""
        from gyroemu.pipelines.formats.atomic import temporaries

        return temporaries(self.folder, (self.path(k).name for k in keys))

    def set_aside(self, keep: Iterable[str], folder: str | Path) -> int:
        """Move every part whose key is not in ``keep`` to ``folder`` (made if missing; a part of the same
        key there is replaced): the store then holds only parts of ``keep``. Returns how many moved."""
        wanted = set(keep)
        others = sorted(self.keys() - wanted)
        if not others:
            return 0
        where = Path(folder)
        where.mkdir(parents=True, exist_ok=True)
        for key in others:
            os.replace(self.path(key), where / self.path(key).name)
        return len(others)

    def write(self, key: str, rows: list[dict[str, Any]]) -> Path:
        """Store ``rows`` (dicts of column: value) as task ``key``'s part, atomically; returns its path."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        from gyroemu.pipelines.formats.atomic import write_atomic

        self.folder.mkdir(parents=True, exist_ok=True)
        if self.schema is not None:
            table = pa.Table.from_pylist(rows, schema=self.schema)
        else:
            table = pa.Table.from_pylist(rows)
        return readable(write_atomic(self.path(key), lambda f: pq.write_table(table, f)))

    def read(self, keys: Iterable[str] | None = None) -> Any:
        """The rows of the parts ``keys`` (default: every part) as one ``pyarrow.Table``; a key without a
        part is left out, and so is a part that cannot be read (with a :class:`StoreWarning`)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        wanted = sorted(self.keys()) if keys is None else [k for k in dict.fromkeys(keys) if self.has(k)]
        tables = []
        for key in wanted:
            try:
                tables.append(pq.read_table(self.path(key), schema=self.schema))
            except (pa.ArrowInvalid, OSError) as exc:
                warnings.warn(
                    f"{self.path(key)}: cannot be read ({exc}): its rows are left out (remove it, and a new run "
                    "runs its task again)",
                    StoreWarning,
                    stacklevel=2,
                )
        if not tables:
            return self.schema.empty_table() if self.schema is not None else pa.table({})
        return pa.concat_tables(tables)

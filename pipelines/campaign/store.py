"""A folder of Parquet part files, one per finished task, written whole or not at all.

Each finished task's rows go to ``<folder>/part-<key>.parquet`` through a temporary file in the same
folder and a rename (:func:`gyroemu.pipelines.formats.atomic.write_atomic`), so a part is either
complete or absent: a campaign stopped at any instant and started again runs exactly the tasks whose
part is missing, and no row is stored twice. The temporary files' names start with a dot, which
Parquet readers skip, so the folder reads as one table at any time::

    pyarrow.dataset.dataset("bench/runs").to_table()       # or pandas.read_parquet("bench/runs")

pyarrow is imported when a part is written or read, not with this module.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

__all__ = ["PartStore", "arrow_schema", "readable"]


def arrow_schema(columns: dict[str, str]) -> Any:
    """A ``pyarrow.Schema`` of ``{column: pyarrow type name}`` (``"float64"``, ``"string"``, ``"bool_"``, ...)."""
    import pyarrow as pa

    return pa.schema([(name, getattr(pa, kind)()) for name, kind in columns.items()])


def readable(path: Path) -> Path:
    """Give ``path`` (a temporary file's 0600 after a rename) the mode a new file gets here: 0666 minus
    the umask, so that the other users of a shared folder (a cluster's) can read it. Returns ``path``."""
    import os

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
        part is left out."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        wanted = sorted(self.keys()) if keys is None else [k for k in dict.fromkeys(keys) if self.has(k)]
        tables = [pq.read_table(self.path(k), schema=self.schema) for k in wanted]
        if not tables:
            return self.schema.empty_table() if self.schema is not None else pa.table({})
        return pa.concat_tables(tables)

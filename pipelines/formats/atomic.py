"""Files written whole or not at all: a temporary file in the target's folder, renamed over the target.

A reader (or a crash) never sees a half-written file at ``path``: the data go to
``.<name>.<random>.tmp`` beside it, which is flushed to the disk (``fsync``) and then moved to ``path`` by
:func:`os.replace` once it is complete, and the folder is synced after the rename; on any error the
temporary file is removed and ``path`` is untouched. Without the first sync a power loss can keep the
rename and lose the data (an empty file at ``path``); without the second, lose the rename. A process
killed mid-write leaves its temporary file: :func:`temporaries` finds those of given names, for a job
that writes them again to remove. The file gets the mode a plain ``open``
would leave it with: an existing file's own, a new one ``0o666`` less the process's umask (the temporary
file's is ``0o600``); where the file system keeps no modes (FAT, some network mounts) it gets what it gets.

:func:`folder_problem` says, before any work, why a folder cannot take an output (missing, not a
folder, read-only or not writable), so that a job refuses it up front naming its argument;
:func:`output_folder_problem` the same of an output folder made when missing, and :func:`output_file_problem`
of an output file (a folder, an input, its folder, an existing file without ``--force``). They live
beside the writer because they answer the question it would otherwise answer too late: can this file be
written here?

An output of several files (a report: its text, its data, its plots) is written whole or not at all by
:func:`staged_files`: each file goes to its temporary file as above, and only once every one of them is
complete are they all renamed into place; on any error (a full disk at the last plot, an interrupt)
every temporary file is removed and the folder is left as it was, an earlier report in it kept.
"""

from __future__ import annotations

import errno
import os
import re
import stat
import tempfile
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from gyroemu.pipelines.formats.file_names import same_file

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "folder_problem",
    "output_file_problem",
    "report_files_problem",
    "output_folder_problem",
    "StagedFiles",
    "staged_files",
    "temporaries",
    "write_atomic",
    "write_text_atomic",
    "write_figure_atomic",
]


def write_atomic(path: str | os.PathLike[str], write: Callable[[IO[Any]], object], *, binary: bool = True) -> Path:
    """Call ``write(f)`` on a temporary file opened for writing (bytes, or UTF-8 text with
    ``binary=False``) and move it to ``path``: an output of one file (:func:`staged_files`). Returns
    ``path``."""
    with staged_files() as out:
        return out.write(path, write, binary=binary)


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` whole or not at all."""
    with staged_files() as out:
        return out.write_text(path, text)


def write_figure_atomic(fig: Figure, path: str | os.PathLike[str], dpi: int) -> Path:
    """Save the matplotlib figure ``fig`` as a PNG at ``path`` whole or not at all, and close it."""
    with staged_files() as out:
        return out.write_figure(fig, path, dpi)


class StagedFiles:
    """The files of one output, each written in full to a temporary file beside it (:meth:`write`,
    :meth:`write_text`, :meth:`write_figure`), and the files it replaces to remove (:meth:`remove`);
    :func:`staged_files` makes one and puts them all in place at the end, or none."""

    def __init__(self) -> None:
        self._staged: list[tuple[str, Path]] = []  # (temporary file, target), in the order written
        self._removals: list[Path] = []

    def write(self, path: str | os.PathLike[str], write: Callable[[IO[Any]], object], *, binary: bool = True) -> Path:
        """Call ``write(f)`` on a new temporary file beside ``path`` (bytes, or UTF-8 text with
        ``binary=False``; removed on any error) that becomes ``path`` when the output is complete. Returns
        ``path``."""
        path = Path(path)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        try:
            synced = False
            with os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", encoding="utf-8") as f:
                write(f)
                if not f.closed:  # the data on the disk before the rename can be
                    f.flush()
                    os.fsync(f.fileno())
                    synced = True
            if not synced:  # ``write`` closed the file itself
                _sync_file(tmp)
            _give_mode(tmp, path)  # mkstemp's 0o600 is for the temporary file, not the output
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        self._staged.append((tmp, path))
        return path

    def write_text(self, path: str | os.PathLike[str], text: str) -> Path:
        """Stage ``text`` (UTF-8) for ``path``."""
        return self.write(path, lambda f: f.write(text), binary=False)

    def write_figure(self, fig: Figure, path: str | os.PathLike[str], dpi: int) -> Path:
        """Stage the matplotlib figure ``fig`` as a PNG for ``path``, and close it."""
        import matplotlib.pyplot as plt

        try:
            return self.write(path, lambda f: fig.savefig(f, dpi=dpi, format="png"))
        finally:
            plt.close(fig)

    def remove(self, path: str | os.PathLike[str]) -> None:
        """Remove ``path`` (if there) when the output is complete, before the staged files are moved in."""
        self._removals.append(Path(path))

    def _commit(self) -> None:
        folders = dict.fromkeys(path.parent for path in self._removals)
        for path in self._removals:
            path.unlink(missing_ok=True)
        while self._staged:
            tmp, path = self._staged[0]
            os.replace(tmp, path)
            folders[path.parent] = None
            del self._staged[0]
        for folder in folders:
            _sync_folder(folder)

    def _discard(self) -> None:
        for tmp, _ in self._staged:
            Path(tmp).unlink(missing_ok=True)
        self._staged.clear()


@contextmanager
def staged_files(folder: str | os.PathLike[str] | None = None) -> Iterator[StagedFiles]:
    """Write an output of several files whole or none of it: the files written through the
    :class:`StagedFiles` given go to temporary files, and when the ``with`` block ends without an error
    the files it named to remove are removed and every staged file is renamed over its target, in the
    order written. On any error (a full disk, ``KeyboardInterrupt``) every temporary file is removed and
    nothing is renamed or removed: the folder is as it was. ``folder``, when given, is made with its
    parents if missing, and the folders made are removed again (if still empty) on an error.

    The renames (each atomic, in the same folder, needing no space) are the only step that can leave
    part of the output: an error between two of them (a failing device) leaves the files already moved
    in place, and the temporary files of the rest removed."""
    made: list[Path] = []
    if folder is not None:
        where = Path(folder)
        while not where.exists() and not where.is_symlink() and where != where.parent:
            made.append(where)
            where = where.parent
        Path(folder).mkdir(parents=True, exist_ok=True)
    staged = StagedFiles()
    try:
        yield staged
        staged._commit()
    except BaseException:
        staged._discard()
        for path in made:  # the deepest first
            try:
                path.rmdir()
            except OSError:
                break
        raise


_TEMPORARY = re.compile(r"^\.(?P<name>.+)\.[a-z0-9_]{8}\.tmp$")
"""A temporary file's name: ``.<name>.<8 characters>.tmp``, as :class:`StagedFiles` (``tempfile.mkstemp``'s
letters, digits and ``_``) and the MCAP log writer (8 hex digits) make them."""


def temporaries(folder: str | os.PathLike[str], names: Iterable[str]) -> list[Path]:
    """The temporary files in ``folder`` of writes to files named ``names`` (``.<name>.<8 characters>.tmp``,
    plain files only), sorted: what a process killed while writing those files left. A job about to write
    them again may remove them; no other file matches. Empty when ``folder`` is missing."""
    wanted = set(names)
    found = []
    try:
        entries = list(os.scandir(folder))
    except (FileNotFoundError, NotADirectoryError):
        return []
    for entry in entries:
        m = _TEMPORARY.match(entry.name)
        if m is not None and m.group("name") in wanted and entry.is_file(follow_symlinks=False):
            found.append(Path(entry.path))
    return sorted(found)


def _sync_file(path: str) -> None:
    """Flush the file ``path``'s data to the disk (``fsync``)."""
    fd = os.open(path, os.O_RDWR)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _sync_folder(folder: Path) -> None:
    """Flush ``folder``'s entries (a rename into it) to the disk: ``fsync`` of the folder, where the system
    and file system can (not on Windows, nor on file systems that refuse it: the rename stands)."""
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:  # a folder cannot be opened here (Windows)
        return
    try:
        os.fsync(fd)
    except OSError as exc:
        if exc.errno not in (errno.EINVAL, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EBADF, errno.EACCES):
            raise
    finally:
        os.close(fd)


def folder_problem(folder: str | os.PathLike[str]) -> str | None:
    """Why ``folder`` cannot take a new file (``"no such folder"``, ``"not a folder"``, ``"read-only file
    system"``, ``"not writable"``), or None when it can: checked with :func:`os.access`, which also
    refuses a read-only mount to root."""
    folder = Path(folder) if str(folder) else Path(".")
    if not folder.exists():
        return "no such folder"
    if not folder.is_dir():
        return "not a folder"
    if os.access(folder, os.W_OK | os.X_OK):
        return None
    try:  # os.access does not say why; statvfs knows a read-only mount
        if os.statvfs(folder).f_flag & os.ST_RDONLY:
            return os.strerror(errno.EROFS).lower()
    except OSError:
        pass
    return "not writable"


def output_folder_problem(folder: str | os.PathLike[str]) -> str | None:
    """Why ``folder``, an output folder made with its parents when missing, cannot take new files:
    ``"<folder> is not a folder"`` for a file there, else ``"<where>: <why>"`` (``where`` the folder, or
    its nearest existing ancestor where it is missing: the folder the first one would be made in); None
    when it can (:func:`folder_problem` of that folder)."""
    folder = Path(folder) if str(folder) else Path(".")
    if folder.exists() and not folder.is_dir():
        return f"{folder} is not a folder"
    where = folder
    while not where.exists() and not where.is_symlink() and where != where.parent:
        where = where.parent
    problem = folder_problem(where)
    return None if problem is None else f"{where}: {problem}"


def report_files_problem(
    folder: str | os.PathLike[str], names: Iterable[str], inputs: Iterable[str | os.PathLike[str]]
) -> str | None:
    """Why a report of files ``names`` written in ``folder`` would write over one of ``inputs`` (by any
    path to it: :func:`output_file_problem`, an earlier report's files being the caller's to refuse), or
    None; a folder still to be made holds no input."""
    folder, inputs = Path(folder), list(inputs)
    if not inputs or not folder.is_dir():
        return None
    for name in names:
        problem = output_file_problem(folder / name, force=True, inputs=inputs)
        if problem is not None:
            return problem
    return None


def output_file_problem(
    path: str | os.PathLike[str],
    *,
    force: bool,
    inputs: Iterable[str | os.PathLike[str]] = (),
) -> str | None:
    """Why the output file ``path`` cannot be written, or None when it can; checked in this order, the
    first that holds is said:

    - ``"<path> is a folder: name a file in it"``;
    - ``"<path> is an input[ (<input>)]: inputs are never overwritten, even with --force"``: ``path`` is
      one of ``inputs`` by any path to it (:func:`~gyroemu.pipelines.formats.file_names.same_file`), the
      input named when given otherwise;
    - ``"<folder>: <why>"``: ``path``'s folder cannot take a new file (:func:`folder_problem`);
    - ``"<path> exists (use --force to overwrite it)"``: a file (or a symbolic link, dangling or not)
      is there and ``force`` is not given.

    A job raises its own error with ``f"argument {argument}: {problem}"``."""
    path = Path(path)
    if path.is_dir():
        return f"{path} is a folder: name a file in it"
    for given in inputs:
        if same_file(path, given):
            alias = "" if os.fspath(given) == os.fspath(path) else f" ({os.fspath(given)})"
            return f"{path} is an input{alias}: inputs are never overwritten, even with --force"
    problem = folder_problem(path.parent)
    if problem is not None:
        return f"{path.parent}: {problem}"
    if (path.exists() or path.is_symlink()) and not force:
        return f"{path} exists (use --force to overwrite it)"
    return None


def _give_mode(tmp: str, path: Path) -> None:
    """Give ``tmp`` the mode ``open`` would leave ``path`` with: its own when it exists, else ``0o666``
    less the umask. A file system that keeps no modes refuses or ignores it: that is no error."""
    try:
        mode = stat.S_IMODE(os.stat(path).st_mode)
    except OSError:  # no file there yet (or none we may stat): a new file's mode
        mode = 0o666 & ~_umask()
    try:
        os.chmod(tmp, mode)
    except OSError:
        pass


def _umask() -> int:
    """The process's umask: from ``/proc/self/status`` where Linux gives it (no change to the process),
    else set and put back at once."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask

"""numba with an on-disk cache that concurrent processes can share safely, for gyroemu's own functions.

gyroemu compiles its recurrences with ``numba`` and caches the machine code on disk
(``cache=True``), so a process pays the compile time once per install, not once per run. numba's
cache is not safe when several processes compile the same functions at the same time: compiled
symbols carry per-process unique numbers, each process writes its own index and code files, and a
process that then loads one function's code written by one process and its caller's written by
another crashes (numba issue #4807). Measured here before this module existed: two processes
starting together from an empty cache, then a third loading it, segfaulted in 1 to 3 rounds of 8.
gyroemu does start processes together (pytest-xdist workers; the demo's publisher, recorder and
filter), so every compile of gyroemu's functions, and every load from the cache, runs under one
inter-process lock:

* :func:`njit` is ``numba.njit`` with ``cache=True`` whose dispatcher compiles under
  :func:`compile_lock`: the lock wraps that one dispatcher's ``compile`` (the path of lazy
  compilation on first call, of a callee compiled while its caller is typed, and of a cache load);
* :func:`guvectorize` takes the lock around numba's eager gufunc build.

Nothing of numba's own is changed: other libraries' compiled functions in the same process compile
as numba alone would compile them.

The lock is ``fcntl.flock`` on a file in the user's cache folder, one per gyroemu version
(``$XDG_CACHE_HOME/gyroemu/<version>/numba.lock``, ``~/.cache`` when unset), re-entrant within a
process (a compile can trigger the compile of a callee). Once the cache is warm, a process takes the
lock once per compiled signature to load it, which costs microseconds.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any

import numba

from gyroemu import __version__

__all__ = ["compile_lock", "guvectorize", "lock_path", "njit"]

_thread_lock = threading.RLock()
_depth = 0
_handle: IO[str] | None = None


def lock_path() -> Path:
    """The lock file: per user (in the user's cache folder) and per gyroemu version."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "gyroemu" / __version__ / "numba.lock"


@contextlib.contextmanager
def compile_lock() -> Iterator[None]:
    """Hold the inter-process numba compile lock (re-entrant within a process)."""
    global _depth, _handle
    with _thread_lock:
        if _depth == 0:
            path = lock_path()
            path.parent.mkdir(parents=True, exist_ok=True)
            _handle = open(path, "a+")
            fcntl.flock(_handle, fcntl.LOCK_EX)
        _depth += 1
        try:
            yield
        finally:
            _depth -= 1
            if _depth == 0 and _handle is not None:
                fcntl.flock(_handle, fcntl.LOCK_UN)
                _handle.close()
                _handle = None


def njit(function: Callable[..., Any] | None = None, **options: Any) -> Any:
    """``numba.njit(cache=True, **options)`` whose compiles and cache loads run under :func:`compile_lock`.

    Used bare (``@njit``) or with numba's options (``@njit(parallel=True)``). Only the returned
    dispatcher is locked: its ``compile`` is replaced on the instance, not on numba's class.
    """
    options.setdefault("cache", True)

    def decorate(fn: Callable[..., Any]) -> Any:
        dispatcher = numba.njit(**options)(fn)
        unlocked = dispatcher.compile

        def compile(sig: Any) -> Any:
            with compile_lock():
                return unlocked(sig)

        compile.__doc__ = unlocked.__doc__
        dispatcher.compile = compile
        return dispatcher

    return decorate(function) if function is not None else decorate


def guvectorize(*args: Any, **kwargs: Any) -> Callable[[Callable[..., Any]], Any]:
    """``numba.guvectorize`` (with ``cache=True``) whose eager build runs under :func:`compile_lock`."""
    kwargs.setdefault("cache", True)
    decorate = numba.guvectorize(*args, **kwargs)

    def locked(function: Callable[..., Any]) -> Any:
        with compile_lock():
            return decorate(function)

    return locked

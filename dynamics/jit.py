"""numba with an on-disk cache that concurrent processes can share safely.

gyroemu compiles its recurrences with ``numba`` and caches the machine code on disk
(``cache=True``), so a process pays the compile time once per install, not once per run. numba's
cache is not safe when several processes compile the same functions at the same time: compiled
symbols carry per-process unique numbers, each process writes its own index and code files, and a
process that then loads one function's code written by one process and its caller's written by
another crashes (numba issue #4807). Measured here before this module existed: two processes
starting together from an empty cache, then a third loading it, segfaulted in 1 to 3 rounds of 8.
gyroemu does start processes together (pytest-xdist workers; the demo's publisher, recorder and
filter), so every compile, and every load from the cache, runs under one inter-process lock:

* :class:`numba.core.dispatcher.Dispatcher`'s ``compile`` (the path of every ``@numba.njit``
  function, lazily compiled on first call or eagerly for a given signature) is wrapped once, when
  this module is first imported (``dynamics/__init__.py`` imports it, so it is in place before any of
  gyroemu's functions compiles);
* :func:`guvectorize` takes the lock around numba's eager gufunc build.

The lock is ``fcntl.flock`` on a file in the temporary folder, re-entrant within a process (a
compile can trigger the compile of a callee). Once the cache is warm, a process takes the lock once
per compiled signature to load it, which costs microseconds.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import tempfile
import threading

import numba
from numba.core.dispatcher import Dispatcher

__all__ = ["compile_lock", "guvectorize"]

_LOCK_PATH = os.path.join(tempfile.gettempdir(), f"gyroemu-numba-{os.getuid()}.lock")
_thread_lock = threading.RLock()
_depth = 0
_handle = None


@contextlib.contextmanager
def compile_lock():
    """Hold the inter-process numba compile lock (re-entrant within a process)."""
    global _depth, _handle
    with _thread_lock:
        if _depth == 0:
            _handle = open(_LOCK_PATH, "a+")
            fcntl.flock(_handle, fcntl.LOCK_EX)
        _depth += 1
        try:
            yield
        finally:
            _depth -= 1
            if _depth == 0:
                fcntl.flock(_handle, fcntl.LOCK_UN)
                _handle.close()
                _handle = None


def _install() -> None:
    if getattr(Dispatcher.compile, "_gyroemu_locked", False):
        return
    unlocked = Dispatcher.compile

    def compile(self, sig):
        with compile_lock():
            return unlocked(self, sig)

    compile._gyroemu_locked = True
    compile.__doc__ = unlocked.__doc__
    Dispatcher.compile = compile


def guvectorize(*args, **kwargs):
    """``numba.guvectorize`` (with ``cache=True``) whose eager build runs under :func:`compile_lock`."""
    kwargs.setdefault("cache", True)
    decorate = numba.guvectorize(*args, **kwargs)

    def locked(function):
        with compile_lock():
            return decorate(function)

    return locked


_install()

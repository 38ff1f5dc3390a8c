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
  compilation on first call, of a callee compiled while its caller is typed, and of a cache load).
  gyroemu compiles nothing else (its quaternion product and rotation are ``njit`` loops, not
  ``guvectorize`` ufuncs, whose build would write numba's cache beside the sources).

Nothing of numba's own is changed: other libraries' compiled functions in the same process compile
as numba alone would compile them.

**numba is imported on first use, not on import.** Importing numba costs about 0.25 s, which a
command that only lists the built-in devices should not pay. So :func:`njit` returns a
:class:`Deferred` that holds the Python function and hands it to numba when it is first
called. A compiled function's compiled callees must be numba dispatchers by the time numba types it:
before handing a function over, its deferred callees (the names its code uses, in its module's
globals or as attributes of a module it uses) are handed over first and put in their place.

The lock is ``fcntl.flock`` on a file in the user's cache folder, one per gyroemu version
(``$XDG_CACHE_HOME/gyroemu/<version>/numba.lock``, ``~/.cache`` when unset), re-entrant within a
process (a compile can trigger the compile of a callee). Once the cache is warm, a process takes the
lock once per compiled signature to load it, which costs microseconds. The compiled functions of
:func:`njit` are cached beside the lock (``…/<version>/numba/``, :func:`cache_path`), through numba's
public cache classes given to each dispatcher (numba's own locators, its class and its config are
untouched); where that folder cannot be written, numba's own cache beside the sources is used.
numba checks a cached function against its own source file only, so a compiled callee edited in
another file would be loaded stale inside its caller; gyroemu's cache entries are stamped with the
content of every file of their compiled callees as well (:func:`callee_files`), and with the options
they were compiled with (numba's index leaves out flags such as ``nogil``).

**Compiled functions release the GIL** (``nogil=True`` unless a function says otherwise): while a
device's kernel loops on one thread, ``simulate``'s writer thread encodes and compresses the previous
block on another. gyroemu's kernels touch only the arrays (and generators) they are given.
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import hashlib
import os
import threading
import types
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any, overload

__all__ = ["Deferred", "cache_path", "callee_files", "compile_lock", "lock_path", "njit", "options_stamp"]

_thread_lock = threading.RLock()
_depth = 0
_handle: IO[str] | None = None


def _user_folder() -> Path:
    """``$XDG_CACHE_HOME/gyroemu/<version>`` (``~/.cache`` when unset): per user and per gyroemu version."""
    import gyroemu

    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    version: str = gyroemu.__version__  # read through the package's module __getattr__, so Any to mypy
    return Path(base) / "gyroemu" / version


def lock_path() -> Path:
    """The lock file: per user (in the user's cache folder) and per gyroemu version."""
    return _user_folder() / "numba.lock"


def cache_path() -> Path:
    """numba's on-disk cache of gyroemu's functions: per user and per gyroemu version, beside the lock."""
    return _user_folder() / "numba"


def _user_cache(py_func: Callable[..., Any], options: dict[str, Any]) -> Any:
    """A numba ``FunctionCache`` of ``py_func`` compiled with numba's ``options``, kept under
    :func:`cache_path` (mirroring the source tree below it, as numba's user-wide cache does), or None
    where numba lacks the public classes this needs (then numba's own cache, beside the sources, is
    used)."""
    flags = options_stamp(options)
    try:
        from numba.core.caching import CompileResultCacheImpl, FunctionCache, UserWideCacheLocator
    except ImportError:
        return None

    class Locator(UserWideCacheLocator):
        def __init__(self, py_func: Callable[..., Any], py_file: str) -> None:
            super().__init__(py_func, py_file)
            self._cache_path = os.path.join(str(cache_path()), self.get_suitable_cache_subpath(py_file))
            self._callee_files = sorted(callee_files(py_func) - {os.path.abspath(py_file)})

        def get_source_stamp(self) -> Any:
            # numba stamps a function's own file only: a compiled callee in another file that changed
            # would be loaded stale, inlined into its caller's cached code. The callees' files count too,
            # and so do the options (numba's index key leaves out flags such as nogil).
            return (super().get_source_stamp(), tuple(_file_stamp(path) for path in self._callee_files), flags)

    class Impl(CompileResultCacheImpl):
        _locator_classes = [Locator]

    class Cache(FunctionCache):
        _impl_class = Impl

    try:
        return Cache(py_func)
    except RuntimeError:  # no locator: a function without a source file
        return None


def options_stamp(options: dict[str, Any]) -> str:
    """numba's compile ``options`` as text that is the same in every process: sorted, and a set option
    (``fastmath={"nsz", "arcp"}``) sorted too, since a set's order follows the strings' hashes, which
    differ from process to process (the ring laser's kernels missed the cache in five runs of six)."""
    return repr(
        sorted((key, sorted(value) if isinstance(value, (set, frozenset)) else value) for key, value in options.items())
    )


def callee_files(py_func: Callable[..., Any]) -> set[str]:
    """The source files of the compiled functions ``py_func`` calls, directly or through others (the
    names its code uses, in its module's globals or as attributes of a module it uses, that are
    :class:`Deferred` or numba dispatchers), its own included."""
    files: set[str] = set()
    seen: set[int] = set()
    todo = [py_func]
    while todo:
        function = todo.pop()
        if id(function) in seen:
            continue
        seen.add(id(function))
        files.add(os.path.abspath(function.__code__.co_filename))
        namespace = function.__globals__
        names = _names_used(function.__code__)
        for name in names:
            value = namespace.get(name)
            members = [value]
            if isinstance(value, types.ModuleType):
                members = [getattr(value, attribute, None) for attribute in names]
            for member in members:
                callee = getattr(member, "py_func", None)
                if isinstance(callee, types.FunctionType):
                    todo.append(callee)
    return files


@functools.lru_cache(maxsize=256)
def _content_stamp(path: str, mtime_ns: int, size: int) -> str:
    with open(path, "rb") as handle:
        return hashlib.sha256(handle.read()).hexdigest()


def _file_stamp(path: str) -> str:
    """A file's content hash (read again only when its time or size changed); "" when it is gone."""
    try:
        st = os.stat(path)
    except OSError:
        return ""
    return _content_stamp(path, st.st_mtime_ns, st.st_size)


def _relocate_cache(holder: Any, attribute: str, py_func: Callable[..., Any], options: dict[str, Any]) -> None:
    """Put :func:`_user_cache` in place of the numba ``FunctionCache`` at ``holder.attribute`` (a
    dispatcher's); where numba keeps its cache elsewhere, leave numba's own."""
    try:
        from numba.core.caching import FunctionCache
    except ImportError:
        return
    if isinstance(getattr(holder, attribute, None), FunctionCache):
        cache = _user_cache(py_func, options)
        if cache is not None:
            setattr(holder, attribute, cache)


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


def _names_used(code: types.CodeType) -> set[str]:
    """Global and attribute names a function's code (and the code nested in it) refers to."""
    names = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            names |= _names_used(const)
    return names


class Deferred:
    """A function to be compiled by numba, handed to numba on first use (see the module's notes).

    Calling it calls the compiled function; any other attribute is the numba object's.
    """

    def __init__(self, function: Callable[..., Any], build: Callable[[Callable[..., Any]], Any]) -> None:
        functools.update_wrapper(self, function)
        self.py_func = function
        self._build = build
        self._compiled: Any = None
        self._building = False

    def compiled(self) -> Any:
        """The numba dispatcher (or gufunc), made on the first call of this method."""
        if self._compiled is None:
            with _thread_lock:
                if self._compiled is None and not self._building:
                    self._building = True
                    try:
                        self._hand_over_callees()
                        self._compiled = self._build(self.py_func)
                    finally:
                        self._building = False
                    namespace = self.py_func.__globals__
                    if namespace.get(self.py_func.__name__) is self:
                        namespace[self.py_func.__name__] = self._compiled
        return self._compiled

    def _hand_over_callees(self) -> None:
        namespace = self.py_func.__globals__
        names = _names_used(self.py_func.__code__)
        for name in names:
            value = namespace.get(name)
            if isinstance(value, Deferred):
                namespace[name] = value.compiled()
            elif isinstance(value, types.ModuleType):
                for attribute in names:
                    member = getattr(value, attribute, None)
                    if isinstance(member, Deferred):
                        setattr(value, attribute, member.compiled())

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return self.compiled()(*args, **kwargs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.compiled(), name)


@overload
def njit(function: Callable[..., Any], **options: Any) -> Any: ...


@overload
def njit(function: None = None, **options: Any) -> Callable[[Callable[..., Any]], Any]: ...


def njit(function: Callable[..., Any] | None = None, **options: Any) -> Any:
    """``numba.njit(cache=True, nogil=True, **options)``, deferred to first use, compiling under
    :func:`compile_lock`.

    Used bare (``@njit``) or with numba's options (``@njit(parallel=True)``). Only the dispatcher made
    here is locked: its ``compile`` is replaced on the instance, not on numba's class. To a type
    checker the decorated function is ``Any`` either way (a :class:`Deferred`, then numba's
    dispatcher), so its annotations check its body, not its callers.
    """
    options.setdefault("cache", True)
    options.setdefault("nogil", True)  # a compiled loop lets the writer's thread run meanwhile

    def build(fn: Callable[..., Any]) -> Any:
        import numba

        dispatcher = numba.njit(**options)(fn)
        if options.get("cache"):
            _relocate_cache(dispatcher, "_cache", fn, options)  # this dispatcher only: numba's class and config stay
        unlocked = dispatcher.compile

        def compile(sig: Any) -> Any:
            with compile_lock():
                return unlocked(sig)

        compile.__doc__ = unlocked.__doc__
        dispatcher.compile = compile
        return dispatcher

    def decorate(fn: Callable[..., Any]) -> Deferred:
        return Deferred(fn, build)

    return decorate(function) if function is not None else decorate

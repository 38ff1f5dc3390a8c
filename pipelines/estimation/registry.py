"""The attitude filters gyroemu knows by name, and a user's own named as ``module:Class``.

================  ===========================================================  ===================
name              filter                                                       needs
================  ===========================================================  ===================
``mekf``          gyroemu's multiplicative (error-state) Kalman filter          —
``madgwick``      Madgwick's gradient-descent filter (``ahrs``)                 —
``mahony``        Mahony's explicit complementary filter (``ahrs``)             —
``ahrs-ekf``      the quaternion EKF of ``ahrs``                                —
``vqf``           VQF, Laidig & Seel (2023)                                     the ``vqf`` extra
``mekf-smooth``   offline: the MEKF forward, then an RTS smoother backward      —
``offline-vqf``   offline: ``vqf.offlineVQF`` (forward and backward)             the ``vqf`` extra
================  ===========================================================  ===================

The two offline filters see the whole log (their ``process`` takes it in one call, a second call is
an error) and are marked ``offline = True``, so a comparison keeps them apart from the online ones
(:func:`is_offline`); they are left out of the default set (:func:`available_filters`) and run when
named.

A setup whose sensors lag the motion (``FilterSetup.gyro_latency_s``, ``mag_latency_s``) gets every
filter, ours, the peers' and a user's alike, wrapped in :class:`~.latency.LatencyCompensated`: the
field at the gyro's instant, the attitudes at their stamps.

Anything else is a user's filter: ``package.module:Class`` (imported; the current folder is tried
too) or ``path/to/file.py:Class``. The class is called with the :class:`FilterSetup` and the object
must have a ``name`` and a ``process(t, gyro, accel, mag=None)`` method (the protocol of
:mod:`gyroemu.pipelines.estimation.protocol`). Each problem raises :class:`FilterError`, whose message names the
argument as given. What its ``process`` returns is checked too when the job asks (``make_filter(...,
argument="--filter")``): a user's filter returning anything but an Estimate of one attitude a sample
(None, say) raises :class:`FilterProtocolError` naming the argument, the filter and what the protocol
asks, where it would otherwise fail later, deep in the job, with a traceback.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import importlib.util
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gyroemu.errors import GyroemuError

from . import protocol
from .latency import LatencyCompensated
from .protocol import PROCESS_PROTOCOL, Estimate, FilterSetup, estimate_problem

__all__ = [
    "FILTERS",
    "FilterError",
    "FilterProtocolError",
    "FilterSpec",
    "available_filters",
    "filter_class",
    "is_offline",
    "learns_in_blocks",
    "make_filter",
    "takes_whole_log",
    "unavailable_filters",
]


class FilterError(ValueError):
    """A filter name or ``module:Class`` that cannot be used; the message names it."""


class FilterProtocolError(GyroemuError, FilterError):
    """A user's filter whose ``process`` broke the protocol (:data:`~.protocol.PROCESS_PROTOCOL`): bad
    input named (the command line's status 2, the message as it is), a :class:`FilterError` too."""


class _ProtocolChecked:
    """A user's filter whose every ``process`` result is checked (:func:`~.protocol.estimate_problem`)
    before anything uses it; every other attribute is the filter's own."""

    def __init__(self, inner: Any, spec: str, argument: str) -> None:
        self._inner, self._spec, self._argument = inner, spec, argument

    def __getattr__(self, name: str) -> Any:  # only for what this object does not have itself
        if name.startswith("_"):  # its own, not set yet (a copy or an unpickling): no endless recursion
            raise AttributeError(name)
        return getattr(self._inner, name)

    def process(self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None = None) -> Estimate:
        est = self._inner.process(t, gyro, accel, mag)
        problem = estimate_problem(est, len(t))
        if problem is not None:
            raise FilterProtocolError(
                f"argument {self._argument}: filter '{self._spec}': {type(self._inner).__name__}.process() returned "
                f"{problem}; {PROCESS_PROTOCOL} (pipelines/estimation/protocol.py)"
            )
        if isinstance(est, Estimate):
            return est
        # an object with a q_wb passes for an Estimate: one it is, with its other fields or None
        return Estimate(
            q_wb=np.asarray(est.q_wb),
            gyro_bias=getattr(est, "gyro_bias", None),
            q_wb_covariance=getattr(est, "q_wb_covariance", None),
        )


@dataclass(frozen=True)
class FilterSpec:
    """A built-in filter: its class's ``module:attribute``, imported only when used."""

    name: str
    target: str
    description: str
    extra: str | None = None  # the optional extra that installs what it needs
    offline: bool = False  # sees the whole log (acausal): compared with offline filters only

    def load(self) -> type:
        """The filter's class; :class:`FilterError` (with the reason) when it cannot be imported."""
        module, _, attr = self.target.partition(":")
        try:
            cls: type = getattr(importlib.import_module(module), attr)
        except ImportError as exc:
            hint = f" (pip install 'gyroemu[{self.extra}]')" if self.extra else ""
            raise FilterError(f"filter '{self.name}' is not available: {exc}{hint}") from exc
        if self.extra == "vqf":  # the adapter imports vqf when made: check now, so the registry can tell
            from .peers import import_vqf

            try:
                import_vqf()
            except ImportError as exc:
                raise FilterError(f"filter '{self.name}' is not available: {exc}") from exc
        return cls


FILTERS: dict[str, FilterSpec] = {
    s.name: s
    for s in (
        FilterSpec(
            "mekf", "gyroemu.pipelines.estimation.mekf:Mekf", "gyroemu's multiplicative Kalman filter (filterpy)"
        ),
        FilterSpec("madgwick", "gyroemu.pipelines.estimation.peers:Madgwick", "Madgwick (ahrs), gain 0.033 / 0.041"),
        FilterSpec("mahony", "gyroemu.pipelines.estimation.peers:Mahony", "Mahony (ahrs), k_P 1, k_I 0.3"),
        FilterSpec("ahrs-ekf", "gyroemu.pipelines.estimation.peers:AhrsEkf", "quaternion EKF (ahrs), default noises"),
        FilterSpec(
            "vqf", "gyroemu.pipelines.estimation.peers:Vqf", "VQF (vqf package), default parameters", extra="vqf"
        ),
        FilterSpec(
            "mekf-smooth",
            "gyroemu.pipelines.estimation.mekf_smoother:MekfSmoother",
            "offline: the MEKF forward, a Rauch-Tung-Striebel smoother backward",
            offline=True,
        ),
        FilterSpec(
            "offline-vqf",
            "gyroemu.pipelines.estimation.peers:OfflineVqf",
            "offline: vqf.offlineVQF, default parameters",
            extra="vqf",
            offline=True,
        ),
    )
}


def is_offline(name_or_spec: str) -> bool:
    """Whether the filter sees the whole log at once (a built-in marked offline, or a class with
    ``offline = True``); a filter that cannot be loaded counts as online."""
    if name_or_spec in FILTERS:
        return FILTERS[name_or_spec].offline
    try:
        return bool(getattr(_user_class(name_or_spec), "offline", False))
    except FilterError:
        return False


def learns_in_blocks(name_or_spec: str) -> bool:
    """Whether the filter named can take a log a block at a time (:func:`.protocol.learns_in_blocks` of
    its class: ``learn`` takes every block, then ``process`` gives the same blocks' estimates, as
    :class:`~.mekf_smoother.MekfSmoother` does); a filter that cannot be loaded cannot."""
    try:
        return protocol.learns_in_blocks(filter_class(name_or_spec))
    except FilterError:
        return False


def takes_whole_log(name_or_spec: str) -> bool:
    """Whether the filter named must be given a log's samples at once: offline (:func:`is_offline`) and
    not learning it a block at a time (:func:`learns_in_blocks`), as ``offline-vqf``."""
    return is_offline(name_or_spec) and not learns_in_blocks(name_or_spec)


def unavailable_filters(*, offline: bool = False) -> dict[str, str]:
    """Built-in filters that cannot run here, with the reason (e.g. VQF without its package): the
    online ones, and the offline ones too with ``offline``."""
    missing = {}
    for name, spec in FILTERS.items():
        if spec.offline and not offline:
            continue
        try:
            spec.load()
        except FilterError as exc:
            missing[name] = str(exc)
    return missing


def available_filters(*, offline: bool = False) -> list[str]:
    """Names of the built-in online filters that can run here, in the table's order (the default set
    of a comparison); with ``offline``, the offline ones too."""
    missing = unavailable_filters(offline=offline)
    return [name for name in FILTERS if name not in missing and (offline or not FILTERS[name].offline)]


class _ReadOnlySourceLoader(importlib.machinery.SourceFileLoader):
    """Python's loader of a source file, but one that writes nothing: a user's filter named by its path
    is read where it is, without a ``__pycache__`` left in their folder (``set_data`` is the one method
    by which a source loader writes its bytecode; ``importlib.abc.SourceLoader`` documents it optional)."""

    def set_data(self, path: str, data: object, *, _mode: int = 0o666) -> None:
        """Write nothing."""


def _user_class(spec: str) -> type:
    module_name, sep, attr = spec.rpartition(":")
    if not sep or not module_name or not attr:
        known = ", ".join(FILTERS)
        raise FilterError(f"unknown filter '{spec}' (known: {known}; or a class of your own as module:Class)")
    if module_name.endswith(".py") or "/" in module_name or "\\" in module_name:
        path = Path(module_name)
        if not path.is_file():
            raise FilterError(f"filter '{spec}': no such file {path}")
        mod_id = f"gyroemu_user_filter_{abs(hash(str(path.resolve())))}"
        loader_spec = importlib.util.spec_from_file_location(
            mod_id, path, loader=_ReadOnlySourceLoader(mod_id, str(path))
        )
        if loader_spec is None or loader_spec.loader is None:
            raise FilterError(f"filter '{spec}': {path} is not a Python file")
        module = importlib.util.module_from_spec(loader_spec)
        try:
            loader_spec.loader.exec_module(module)
        except Exception as exc:  # noqa: BLE001 - any error in the user's file is reported as theirs
            raise FilterError(f"filter '{spec}': importing {path} failed: {type(exc).__name__}: {exc}") from exc
    else:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name is None or not module_name.startswith(exc.name):
                raise FilterError(f"filter '{spec}': importing '{module_name}' failed: {exc}") from exc
            cwd = str(Path.cwd())
            if cwd in sys.path:
                raise FilterError(f"filter '{spec}': no module named '{module_name}'") from exc
            sys.path.insert(0, cwd)  # `gyroemu` as a console script does not look in the current folder
            try:
                module = importlib.import_module(module_name)
            except ModuleNotFoundError:
                raise FilterError(
                    f"filter '{spec}': no module named '{module_name}' (looked in the current folder too)"
                ) from exc
            finally:
                sys.path.remove(cwd)
        except Exception as exc:  # noqa: BLE001
            raise FilterError(
                f"filter '{spec}': importing '{module_name}' failed: {type(exc).__name__}: {exc}"
            ) from exc
    try:
        cls: type = getattr(module, attr)
    except AttributeError:
        raise FilterError(f"filter '{spec}': module '{module_name}' has no attribute '{attr}'") from None
    if not callable(cls):
        raise FilterError(f"filter '{spec}': '{attr}' is not a class")
    return cls


def filter_class(name_or_spec: str) -> type:
    """The class a filter argument names: a built-in name or ``module:Class``."""
    if name_or_spec in FILTERS:
        return FILTERS[name_or_spec].load()
    return _user_class(name_or_spec)


def make_filter(name_or_spec: str, setup: FilterSetup, *, argument: str | None = None) -> protocol.AttitudeFilter:
    """A filter object for ``setup``: a built-in name (``FILTERS``) or a user's ``module:Class``. With
    ``argument`` (the command line's, ``"--filter"``), a user's filter has what its ``process`` returns
    checked on every call (type, shapes: :func:`~.protocol.estimate_problem`), which raises
    :class:`FilterProtocolError` naming ``argument``, the filter and what the protocol asks; the
    built-ins are not wrapped (their results, and their speed, are as without it).

    Raises
    ------
    FilterError
        Unknown name, a built-in that cannot run here (VQF without its package), a ``module:Class``
        that does not import, or an object without ``name`` and a callable ``process``. The message
        names ``name_or_spec``.
    FilterProtocolError
        From ``process``, with ``argument``: a user's filter's return value that is no Estimate of one
        attitude a sample.
    """
    cls = filter_class(name_or_spec)
    try:
        filt: protocol.AttitudeFilter = cls(setup)  # checked against the protocol below
    except FilterError:
        raise
    except Exception as exc:  # noqa: BLE001 - a user's constructor failing is the user's argument at fault
        raise FilterError(
            f"filter '{name_or_spec}': {getattr(cls, '__name__', cls)}(setup) failed: {type(exc).__name__}: {exc}"
        ) from exc
    missing = [a for a in ("name", "process") if not hasattr(filt, a)]
    if missing or not callable(filt.process):
        what = " and ".join(f"'{a}'" for a in missing) if missing else "a callable 'process'"
        raise FilterError(
            f"filter '{name_or_spec}': {type(filt).__name__} has no {what}; a filter needs a "
            "'name' and 'process(t, gyro, accel, mag=None)' (see pipelines/estimation/protocol.py)"
        )
    if not isinstance(filt.name, str) or not filt.name:
        raise FilterError(f"filter '{name_or_spec}': its 'name' must be a non-empty string, got {filt.name!r}")
    if argument is not None and name_or_spec not in FILTERS:  # checked where it returns, under the latency's moves
        filt = _ProtocolChecked(filt, name_or_spec, argument)
    if setup.gyro_latency_s or setup.mag_latency_s:  # every filter moved in time by the same rules
        return LatencyCompensated(filt, setup.gyro_latency_s, setup.mag_latency_s)
    return filt

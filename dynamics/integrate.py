"""The general-purpose integrator: DOP853 with dense output, split into segments at state jumps.

Method
------
Each smooth stretch of the motion is integrated by :func:`scipy.integrate.solve_ivp` with ``DOP853``
(Dormand & Prince's explicit Runge–Kutta 8(5,3) with a 7th-order dense output; Hairer, Nørsett &
Wanner, *Solving ODEs I*, §II.10), tight tolerances, and its dense output evaluated at the output
times that fall in the stretch, all at once. The stretches end at

* **scheduled jumps** (:class:`Jump`): at a known time the state is replaced by ``apply(t, y)``, e.g.
  an impulse ``ΔP = J, ΔL = r × J``; with ``apply=None`` it is only a breakpoint, where the derivative
  may change discontinuously (a command that switches on) and the solver must not step across;
* **detected events** (:class:`Event`): ``condition(t, y)`` crosses zero (in ``direction``), located
  by the solver's root finder, and ``apply(t, y)`` gives the new state (a contact impulse). An event's
  ``apply`` may return a :class:`Jumped` to also add breakpoints (the end of a contact pulse) and
  schedule later jumps.

A sample at the time of a jump sees the state *after* it (the trajectory is right-continuous). The
quaternion part of the state (``quaternion``, default ``[3:7]``) is renormalised at every segment
boundary and at every output; between them the solver integrates it freely (its norm drifts by about
the tolerance; the equations of motion use the normalised rotation).

The derivative ``fun(t, y)`` must also accept a column of times ``(k,)`` with states ``(k, n)``: it is
called so at the outputs of each segment, to return the exact state derivative there (accelerations
are read from it, never differenced).
"""

from __future__ import annotations

import bisect
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Jump", "Jumped", "Event", "Solution", "integrate"]

Derivative = Callable[[ArrayLike, NDArray[np.float64]], NDArray[np.float64]]


@dataclass(frozen=True)
class Jumped:
    """What an event's ``apply`` may return: the new state, times the solver must stop at, and jumps
    to schedule later (:class:`Jump`)."""

    y: NDArray[np.float64]
    breakpoints: Sequence[float] = ()
    jumps: Sequence[Jump] = ()


@dataclass(frozen=True)
class Jump:
    """A state jump at a known time ``t``: ``y⁺ = apply(t, y⁻)``; ``apply=None`` is a bare breakpoint."""

    t: float
    apply: Callable[[float, NDArray[np.float64]], NDArray[np.float64]] | None = None


@dataclass(frozen=True)
class Event:
    """A jump where ``condition(t, y)`` crosses zero.

    Attributes
    ----------
    condition : callable (t, y) -> float
        Continuous within each segment.
    apply : callable (t, y) -> ndarray or Jumped or None
        The state after the event (``None``: no change).
    direction : float
        ``-1``: only falling crossings trigger (positive to negative), ``+1`` rising, ``0`` both.
    pending : callable (t, y) -> bool, optional
        Checked at the start of every segment: when true, ``apply`` is called there at once (a contact
        already closing when a previous pulse ends).
    """

    condition: Callable[[float, NDArray[np.float64]], float]
    apply: Callable[[float, NDArray[np.float64]], ArrayLike | Jumped | None]
    direction: float = -1.0
    pending: Callable[[float, NDArray[np.float64]], bool] | None = None


@dataclass
class Solution:
    """Sampled states and what happened between them.

    Attributes
    ----------
    t : ndarray (N,)
        Output times, s.
    y : ndarray (N, n)
        States (quaternion renormalised).
    y_dot : ndarray (N, n)
        ``fun(t, y)`` at the outputs, evaluated with the segment each output belongs to.
    jumps : list of (t, y_before, y_after)
        Every jump applied, in time order.
    n_steps, n_fun : int
        Accepted solver steps and derivative evaluations, summed over segments.
    """

    t: NDArray[np.float64]
    y: NDArray[np.float64]
    y_dot: NDArray[np.float64]
    jumps: list[tuple[float, NDArray[np.float64], NDArray[np.float64]]] = field(default_factory=list)
    n_steps: int = 0
    n_fun: int = 0


_Action = Callable[[float, NDArray[np.float64]], ArrayLike | Jumped | None]
"""A jump's or an event's ``apply``: the state after it (``None``: no change), or a :class:`Jumped`."""


class _SolverEvent(Protocol):
    """An event as :func:`scipy.integrate.solve_ivp` takes it: a function of ``(t, y)`` that carries its
    ``terminal`` and ``direction`` as attributes."""

    terminal: bool
    direction: float

    def __call__(self, tt: float, yy: NDArray[np.float64], /) -> float: ...


def _normalised(y: NDArray[np.float64], quaternion: slice | None) -> NDArray[np.float64]:
    if quaternion is None:
        return y
    y = np.array(y, dtype=float)
    y[..., quaternion] /= np.linalg.norm(y[..., quaternion], axis=-1, keepdims=True)
    return y


def _as_jumped(result: ArrayLike | Jumped | None, y: NDArray[np.float64]) -> Jumped:
    if result is None:
        return Jumped(y)
    if isinstance(result, Jumped):
        return result
    return Jumped(np.asarray(result, dtype=float))


def integrate(
    fun: Derivative,
    t_out: ArrayLike,
    y0: ArrayLike,
    *,
    t0: float | None = None,
    jumps: Sequence[Jump] = (),
    events: Sequence[Event] = (),
    rtol: float = 1e-10,
    atol: float | NDArray[np.float64] = 1e-12,
    max_step: float = np.inf,
    quaternion: slice | None = slice(3, 7),
    max_segments: int = 100_000,
) -> Solution:
    """Integrate ``ẏ = fun(t, y)`` from ``y0`` at ``t0`` and sample the solution at ``t_out``.

    Parameters
    ----------
    fun : callable (t, y) -> ndarray
        The derivative, for ``y`` of shape ``(n,)`` and, at the outputs, ``(k, n)`` with ``t`` ``(k,)``.
    t_out : array_like (N,)
        Increasing output times; the integration runs to ``t_out[-1]``.
    y0 : array_like (n,)
        State at ``t0`` (default ``t_out[0]``).
    jumps : sequence of Jump
        Scheduled jumps and breakpoints; those outside ``[t0, t_out[-1])`` are ignored.
    events : sequence of Event
        Detected jumps.
    rtol, atol : DOP853's relative and absolute tolerances (per step local error).
    max_step : float
        Largest step, s (``inf``: the solver chooses).
    quaternion : slice or None
        Where the quaternion sits in the state, renormalised at boundaries and outputs.
    max_segments : int
        Guard against an event that keeps firing.

    Returns
    -------
    Solution
    """
    t_out = np.asarray(t_out, dtype=float)
    if t_out.ndim != 1 or t_out.size == 0 or np.any(np.diff(t_out) < 0):
        raise ValueError("t_out must be a non-empty increasing 1-D array")
    t_end = float(t_out[-1])
    t = float(t_out[0]) if t0 is None else float(t0)
    if t > t_out[0]:
        raise ValueError(f"t0 = {t} is after the first output time {t_out[0]}")
    y = _normalised(np.asarray(y0, dtype=float), quaternion)

    # Scheduled stops: time-ordered, each with its jump (or None for a bare breakpoint).
    stops: list[tuple[float, int, _Action | None]] = []
    for k, jump in enumerate(jumps):
        if t <= jump.t < t_end or (jump.t == t_end and jump.apply is None):
            stops.append((float(jump.t), k, jump.apply))
    stops.sort(key=lambda s: (s[0], s[1]))
    counter = len(stops)

    def add_stops(times: Sequence[float], actions: Sequence[_Action | None] | None = None) -> None:
        nonlocal counter
        for bt, action in zip(times, actions or [None] * len(times)):
            if t < bt < t_end:
                bisect.insort(stops, (float(bt), counter, action), key=lambda s: (s[0], s[1]))
                counter += 1

    def solver_events(t_start: float) -> list[_SolverEvent] | None:
        """The events for solve_ivp on a segment starting at ``t_start``. A condition that is exactly
        zero there (the event that just acted, at its root) is taken as lying on its pre-crossing side,
        so that the root finder looks for the next crossing instead of returning ``t_start`` again."""
        out: list[_SolverEvent] = []
        for ev in events:

            def g(tt: float, yy: NDArray[np.float64], ev: Event = ev) -> float:
                value = ev.condition(tt, yy)
                if tt == t_start and value == 0.0:
                    before: float = -np.copysign(np.finfo(float).tiny, ev.direction or -1.0)
                    return before
                return value

            event = cast(_SolverEvent, g)  # a function's attributes, which mypy cannot type on a def
            event.terminal = True
            event.direction = ev.direction
            out.append(event)
        return out or None

    n = y.size
    y_out = np.empty((t_out.size, n))
    y_dot = np.empty((t_out.size, n))
    filled = np.zeros(t_out.size, dtype=bool)
    history: list[tuple[float, NDArray[np.float64], NDArray[np.float64]]] = []
    n_steps = n_fun = 0

    def apply_jump(tt: float, yy: NDArray[np.float64], action: _Action) -> NDArray[np.float64]:
        result = _as_jumped(action(tt, yy), yy)
        after = _normalised(result.y, quaternion)
        history.append((tt, yy.copy(), after.copy()))
        add_stops(list(result.breakpoints))
        add_stops([j.t for j in result.jumps], [j.apply for j in result.jumps])
        return after

    for _ in range(max_segments):
        # Jumps due now (scheduled at this time, or events already pending).
        while stops and stops[0][0] <= t:
            _, _, action = stops.pop(0)
            if action is not None:
                y = apply_jump(t, y, action)
        for ev in events:
            if ev.pending is not None and ev.pending(t, y):
                y = apply_jump(t, y, ev.apply)

        t_stop = stops[0][0] if stops else t_end
        last = t_stop >= t_end
        if t_stop > t:
            from scipy.integrate import solve_ivp  # scipy where it is used: the CLI's listings skip it

            sol = solve_ivp(
                fun,
                (t, t_stop),
                y,
                method="DOP853",
                dense_output=True,
                events=solver_events(t),
                rtol=rtol,
                atol=atol,
                max_step=max_step,
            )
            if sol.status < 0:
                raise RuntimeError(f"integration failed at t = {sol.t[-1]:.9g} s: {sol.message}")
            n_steps += sol.t.size - 1
            n_fun += sol.nfev
            t_next, y_next = float(sol.t[-1]), sol.y[:, -1]
            fired = [k for k, te in enumerate(sol.t_events or []) if te.size]
            if fired:
                last = False
            # Outputs in [t, t_next), or [t, t_next] on the final segment.
            mask = (t_out >= t) & ((t_out < t_next) | (last & (t_out <= t_next))) & ~filled
            if np.any(mask):
                ys = _normalised(np.atleast_2d(sol.sol(t_out[mask]).T), quaternion)
                y_out[mask] = ys
                y_dot[mask] = fun(t_out[mask], ys)
                filled |= mask
            t, y = t_next, _normalised(y_next, quaternion)
            if fired:
                # The first event that fired acts; an ``apply`` that must handle simultaneous events
                # (several corners touching at once) does so itself, or through ``pending``.
                y = apply_jump(t, y, events[fired[0]].apply)
        else:
            mask = (t_out == t) & ~filled & last
            if np.any(mask):
                y_out[mask] = y
                y_dot[mask] = fun(t_out[mask], np.broadcast_to(y, (int(mask.sum()), n)))
                filled |= mask
        if last and t >= t_end:
            break
    else:
        raise RuntimeError(f"more than {max_segments} segments: an event keeps firing near t = {t:.9g} s")

    if not filled.all():  # outputs before t0 cannot happen; this is a guard against a logic error
        raise RuntimeError("some output times were not reached")
    return Solution(t=t_out, y=y_out, y_dot=y_dot, jumps=history, n_steps=n_steps, n_fun=n_fun)

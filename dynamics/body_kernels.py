"""Small vectorised kernels of the integrated rigid bodies: rotation matrices, cross and Hamilton products.

The equations of motion of :mod:`gyroemu.dynamics.rigid_body`, :mod:`gyroemu.dynamics.gyrostat` and the
scenarios integrated on them (:mod:`gyroemu.dynamics.impact`, :mod:`gyroemu.dynamics.vessels`) call these
for every step of the integrator, mostly on single states. They are written out in plain floats for single
vectors and quaternions, where numpy's general routines (``numpy.cross``, the compiled ufunc
:func:`gyroemu.dynamics.rotation.quat_multiply`) cost more in call overhead than in arithmetic, and in
broadcasting array operations for whole sampled trajectories.

Conventions: quaternions ``(w, x, y, z)``, Hamilton product, ``R(q)`` turns body axes into world axes.
Every function takes single vectors or stacks of them (leading axes broadcast).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .rotation import quat_multiply

__all__ = ["rotation_matrix", "rotate", "rotate_back", "cross", "stack_state", "pure_quat", "quat_product"]


def rotation_matrix(q: ArrayLike) -> NDArray[np.float64]:
    """``R(q)`` of shape ``(..., 3, 3)`` from quaternions ``q`` ``(..., 4)``; ``q`` need not be of unit norm
    (it is normalised first)."""
    q = np.asarray(q, dtype=float)
    if q.ndim == 1:  # the integrator's case: plain floats are several times faster than array ops
        w, x, y, z = q.tolist()
        n = 1.0 / (w * w + x * x + y * y + z * z)
        return np.array(
            [
                [1 - 2 * (y * y + z * z) * n, 2 * (x * y - w * z) * n, 2 * (x * z + w * y) * n],
                [2 * (x * y + w * z) * n, 1 - 2 * (x * x + z * z) * n, 2 * (y * z - w * x) * n],
                [2 * (x * z - w * y) * n, 2 * (y * z + w * x) * n, 1 - 2 * (x * x + y * y) * n],
            ]
        )
    unit = q / np.sqrt(np.sum(q * q, axis=-1, keepdims=True))
    w, x, y, z = unit[..., 0], unit[..., 1], unit[..., 2], unit[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def rotate(r: NDArray[np.float64], v: ArrayLike) -> NDArray[np.float64]:
    """``R v`` for matrices ``(..., 3, 3)`` and vectors ``(..., 3)``: body to world; returns ``(..., 3)``."""
    rv: NDArray[np.float64] = np.matmul(r, np.asarray(v, dtype=float)[..., None])[..., 0]
    return rv


def rotate_back(r: NDArray[np.float64], v: ArrayLike) -> NDArray[np.float64]:
    """``Rᵀ v`` for matrices ``(..., 3, 3)`` and vectors ``(..., 3)``: world to body; returns ``(..., 3)``."""
    vr: NDArray[np.float64] = np.matmul(np.asarray(v, dtype=float)[..., None, :], r)[..., 0, :]
    return vr


def cross(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """``a × b`` over the last axis, broadcasting (``numpy.cross`` without its overhead); ``(..., 3)``."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.ndim == 1 and b.ndim == 1:
        a1, a2, a3 = a.tolist()
        b1, b2, b3 = b.tolist()
        return np.array([a2 * b3 - a3 * b2, a3 * b1 - a1 * b3, a1 * b2 - a2 * b1])
    a1, a2, a3 = a[..., 0], a[..., 1], a[..., 2]
    b1, b2, b3 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a2 * b3 - a3 * b2, a3 * b1 - a1 * b3, a1 * b2 - a2 * b1], axis=-1)


def stack_state(lead: tuple[int, ...], parts: Sequence[NDArray[np.float64]]) -> NDArray[np.float64]:
    """Concatenate state parts ``(..., k_i)`` along the last axis, broadcasting each to the leading shape
    ``lead``; returns ``lead + (Σ k_i,)``."""
    return np.concatenate(
        [a if a.shape[:-1] == lead else np.broadcast_to(a, lead + a.shape[-1:]) for a in parts], axis=-1
    )


def pure_quat(omega: ArrayLike) -> NDArray[np.float64]:
    """The pure quaternion ``(0, ω)`` ``(..., 4)`` of vectors ``ω`` ``(..., 3)`` (any unit, e.g. rad/s)."""
    omega = np.asarray(omega, dtype=float)
    return np.concatenate([np.zeros(omega.shape[:-1] + (1,)), omega], axis=-1)


def quat_product(p: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Hamilton product ``p ⊗ q`` of quaternions ``(..., 4)``: :func:`gyroemu.dynamics.rotation.quat_multiply`,
    with plain floats for two single quaternions (the integrator's case, where they beat the compiled ufunc's
    call overhead)."""
    if p.ndim == 1 and q.ndim == 1:
        pw, px, py, pz = p.tolist()
        qw, qx, qy, qz = q.tolist()
        return np.array(
            [
                pw * qw - px * qx - py * qy - pz * qz,
                pw * qx + px * qw + py * qz - pz * qy,
                pw * qy - px * qz + py * qw + pz * qx,
                pw * qz + px * qy - py * qx + pz * qw,
            ]
        )
    return quat_multiply(p, q)

"""Rotations, vectorised over leading axes.

Conventions (``interface.md``): Hamilton quaternions, unit norm, stored scalar-first ``(w, x, y, z)``
in arrays of shape ``(..., 4)``. ``q_wb`` rotates a body-frame vector into the world frame:
``v_w = q_wb ⊗ v_b ⊗ q_wb*``, and ``R(q_wb)`` is the matrix that does the same.

Conversions defer to :class:`scipy.spatial.transform.Rotation` (imported where used: importing
scipy.spatial costs 0.25 s, which the command line's listings should not pay); the product and the
vector rotation, which sit on hot paths, are compiled numba loops over rows, broadcast like numpy
(about 3x faster than the same formulas in numpy on millions of samples, which allocate a temporary
per term), and cached with gyroemu's other compiled functions (:mod:`.jit`).

Euler angles
------------
* Z-X-Z (precession φ, nutation θ, spin ψ), the lecture's top angles: ``R = Rz(φ) Rx(θ) Rz(ψ)``,
  each about the axis as already moved (intrinsic).
* Z-Y-X (yaw ψ, pitch θ, roll φ), the vehicle angles: ``R = Rz(ψ) Ry(θ) Rx(φ)``, intrinsic; arrays
  hold ``(roll, pitch, yaw)`` in that order, as ROS and most datasheets list them.
"""

from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .jit import njit

if TYPE_CHECKING:
    from scipy.spatial.transform import Rotation

__all__ = [
    "quat_multiply",
    "quat_conjugate",
    "quat_normalize",
    "quat_positive",
    "quat_exp",
    "quat_log",
    "quat_from_rotvec",
    "quat_to_rotvec",
    "quat_slerp",
    "quat_interpolate",
    "quat_rotate",
    "quat_to_matrix",
    "quat_from_matrix",
    "quat_from_euler_zxz",
    "euler_zxz_from_quat",
    "quat_from_euler_zyx",
    "euler_zyx_from_quat",
    "quat_angle",
    "skew",
    "body_rate_from_quat_derivative",
    "body_rate_from_euler_zxz",
    "body_rate_from_euler_zyx",
    "half_turn",
    "hamilton_product",
    "set_product",
    "rotate_body",
]


def _q(q: ArrayLike) -> NDArray[np.float64]:
    q = np.asarray(q, dtype=float)
    if q.shape[-1] != 4:
        raise ValueError(f"quaternions need a last axis of length 4 (w, x, y, z), got shape {q.shape}")
    return q


def _v(v: ArrayLike) -> NDArray[np.float64]:
    v = np.asarray(v, dtype=float)
    if v.shape[-1] != 3:
        raise ValueError(f"vectors need a last axis of length 3, got shape {v.shape}")
    return v


# Scalar steps for compiled loops (a strapdown integration, a filter's error injection): one quaternion
# at a time, renormalised, so that a long loop of them stays on the unit sphere.


@njit
def half_turn(
    phi_x: float, phi_y: float, phi_z: float
) -> tuple[float, float, float, float]:  # pragma: no cover - compiled
    """exp(φ/2) = (cos |φ|/2, sin(|φ|/2) φ/|φ|) of a rotation vector φ (rad), as (w, x, y, z)."""
    angle = math.sqrt(phi_x * phi_x + phi_y * phi_y + phi_z * phi_z)
    s = math.sin(0.5 * angle) / angle if angle > 1e-12 else 0.5 - angle * angle / 48.0
    return math.cos(0.5 * angle), phi_x * s, phi_y * s, phi_z * s


@njit
def hamilton_product(
    aw: float, ax: float, ay: float, az: float, bw: float, bx: float, by: float, bz: float
) -> tuple[float, float, float, float]:  # pragma: no cover - compiled
    """a ⊗ b (Hamilton) of two quaternions given by their components, as (w, x, y, z); not renormalised."""
    w = aw * bw - ax * bx - ay * by - az * bz
    x = aw * bx + ax * bw + ay * bz - az * by
    y = aw * by - ax * bz + ay * bw + az * bx
    z = aw * bz + ax * by - ay * bx + az * bw
    return w, x, y, z


@njit
def set_product(
    q: NDArray[np.float64], aw: float, ax: float, ay: float, az: float, bw: float, bx: float, by: float, bz: float
) -> None:  # pragma: no cover - compiled
    """q ← a ⊗ b (Hamilton), renormalised; ``q`` (4,) in place (it may hold a or b)."""
    w, x, y, z = hamilton_product(aw, ax, ay, az, bw, bx, by, bz)
    n = math.sqrt(w * w + x * x + y * y + z * z)
    q[0], q[1], q[2], q[3] = w / n, x / n, y / n, z / n


@njit
def rotate_body(
    q: NDArray[np.float64], phi_x: float, phi_y: float, phi_z: float
) -> None:  # pragma: no cover - compiled
    """q ← q ⊗ exp(φ/2) for a body-frame rotation vector φ (rad): the strapdown step."""
    c, dx, dy, dz = half_turn(phi_x, phi_y, phi_z)
    set_product(q, q[0], q[1], q[2], q[3], c, dx, dy, dz)


@njit
def _multiply_rows(
    p: NDArray[np.float64], q: NDArray[np.float64], out: NDArray[np.float64]
) -> None:  # pragma: no cover - compiled
    for i in range(out.shape[0]):
        pw, px, py, pz = p[i, 0], p[i, 1], p[i, 2], p[i, 3]
        qw, qx, qy, qz = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
        out[i, 0] = pw * qw - px * qx - py * qy - pz * qz
        out[i, 1] = pw * qx + px * qw + py * qz - pz * qy
        out[i, 2] = pw * qy - px * qz + py * qw + pz * qx
        out[i, 3] = pw * qz + px * qy - py * qx + pz * qw


def _rows(
    a: NDArray[np.float64], b: NDArray[np.float64], width: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], tuple[int, ...]]:
    """``a`` and ``b`` broadcast over their leading axes and viewed as rows, the output rows of ``width``
    values, and the output's leading shape (the rows are views where the shapes allow)."""
    lead = a.shape[:-1]
    if b.shape[:-1] != lead:
        lead = np.broadcast_shapes(lead, b.shape[:-1])
        a = np.broadcast_to(a, lead + a.shape[-1:])
        b = np.broadcast_to(b, lead + b.shape[-1:])
    a2, b2 = a.reshape(-1, a.shape[-1]), b.reshape(-1, b.shape[-1])
    return a2, b2, np.empty((a2.shape[0], width)), lead


def quat_multiply(p: ArrayLike, q: ArrayLike) -> NDArray[np.float64]:
    """Hamilton product ``p ⊗ q``; shapes ``(..., 4)`` broadcast against each other."""
    a, b, out, lead = _rows(_q(p), _q(q), 4)
    _multiply_rows(a, b, out)
    return out.reshape(lead + (4,))


def quat_conjugate(q: ArrayLike) -> NDArray[np.float64]:
    """Conjugate ``(w, -x, -y, -z)``: the inverse of a unit quaternion."""
    q = _q(q)
    conjugate: NDArray[np.float64] = q * np.array([1.0, -1.0, -1.0, -1.0])
    return conjugate


def quat_normalize(q: ArrayLike) -> NDArray[np.float64]:
    """Scale each quaternion to unit norm; a zero quaternion raises ``ValueError``."""
    q = _q(q)
    n: NDArray[np.float64] = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n == 0):
        raise ValueError("cannot normalise a zero quaternion")
    return q / n


def quat_positive(q: ArrayLike) -> NDArray[np.float64]:
    """The same rotations with ``w >= 0`` (``q`` and ``-q`` are one rotation)."""
    q = _q(q)
    return np.where(q[..., :1] < 0, -q, q)


def quat_exp(v: ArrayLike) -> NDArray[np.float64]:
    """Exponential of the pure quaternion ``(0, v)``: ``(cos|v|, sin|v| v/|v|)``.

    A rotation by angle ``θ`` about unit axis ``n`` is ``quat_exp(θ n / 2)``.
    """
    v = _v(v)
    a = np.linalg.norm(v, axis=-1, keepdims=True)
    # sin(a)/a with its Taylor series near 0, where the quotient loses digits.
    k = np.where(a < 1e-4, 1.0 - a * a / 6.0, np.sin(a) / np.where(a == 0, 1.0, a))
    return np.concatenate([np.cos(a), k * v], axis=-1)


def quat_log(q: ArrayLike) -> NDArray[np.float64]:
    """Logarithm of a unit quaternion: the vector part ``v`` of ``log q = (0, v)``, ``|v| <= π/2``
    after choosing the sign with ``w >= 0``. Inverse of :func:`quat_exp` on that range."""
    q = quat_positive(q)
    w = np.clip(q[..., :1], -1.0, 1.0)
    s = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    a = np.arctan2(s, w)
    k: NDArray[np.float64] = np.where(s < 1e-8, 1.0 + a * a / 6.0, a / np.where(s == 0, 1.0, s))
    return k * q[..., 1:]


def quat_from_rotvec(phi: ArrayLike) -> NDArray[np.float64]:
    """Quaternion of the rotation vector ``phi`` (axis times angle, rad)."""
    return quat_exp(0.5 * _v(phi))


def quat_to_rotvec(q: ArrayLike) -> NDArray[np.float64]:
    """Rotation vector (axis times angle in ``[0, π]``, rad) of unit quaternions."""
    return 2.0 * quat_log(q)


def quat_slerp(q0: ArrayLike, q1: ArrayLike, s: ArrayLike) -> NDArray[np.float64]:
    """Spherical linear interpolation ``q0 ⊗ (q0* ⊗ q1)^s`` along the shorter arc.

    ``s`` is the fraction (0 gives ``q0``, 1 gives ``q1``) and broadcasts against the quaternions'
    leading axes.
    """
    q0, q1 = _q(q0), _q(q1)
    d = quat_log(quat_multiply(quat_conjugate(q0), q1))
    return quat_multiply(q0, quat_exp(np.asarray(s, dtype=float)[..., None] * d))


@njit
def _interpolate_rows(
    t: NDArray[np.float64], q: NDArray[np.float64], t_query: NDArray[np.float64], out: NDArray[np.float64]
) -> None:  # pragma: no cover - compiled
    n = t.shape[0]
    for i in range(t_query.shape[0]):
        tq = t_query[i]
        # Interval k with t[k] < tq <= t[k + 1] (t[0] itself: interval 0), as scipy's Slerp picks it.
        lo, hi = 0, n - 1
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if t[mid] < tq:
                lo = mid
            else:
                hi = mid
        k = lo
        aw, ax, ay, az = q[k, 0], q[k, 1], q[k, 2], q[k, 3]
        bw, bx, by, bz = q[k + 1, 0], q[k + 1, 1], q[k + 1, 2], q[k + 1, 3]
        # d = q_k* ⊗ q_{k+1}, taken along the shorter arc (w >= 0)
        dw = aw * bw + ax * bx + ay * by + az * bz
        sign = 1.0
        if dw < 0.0:
            sign = -1.0
        if tq == t[k + 1]:  # a sample instant: the sample itself, on the side of the shorter arc
            out[i, 0], out[i, 1], out[i, 2], out[i, 3] = sign * bw, sign * bx, sign * by, sign * bz
            continue
        s = (tq - t[k]) / (t[k + 1] - t[k])
        if s == 0.0:
            out[i, 0], out[i, 1], out[i, 2], out[i, 3] = aw, ax, ay, az
            continue
        dx = sign * (aw * bx - ax * bw - ay * bz + az * by)
        dy = sign * (aw * by + ax * bz - ay * bw - az * bx)
        dz = sign * (aw * bz - ax * by + ay * bx - az * bw)
        dw = sign * dw
        v = np.sqrt(dx * dx + dy * dy + dz * dz)
        half = np.arctan2(v, dw)  # half the angle of d
        # d^s = (cos(s·half), sin(s·half) d_v/|d_v|), |d_v| = sin(half). Where |d_v| is tiny (0 when the
        # samples are equal), sin(s·half)/sin(half) = s (1 + (1 − s²) half²/6 + …) = s to round-off.
        if v < 1e-8:
            k_v = s
        else:
            k_v = np.sin(s * half) / v
        ew, ex, ey, ez = np.cos(s * half), k_v * dx, k_v * dy, k_v * dz
        out[i, 0] = aw * ew - ax * ex - ay * ey - az * ez  # q_k ⊗ d^s
        out[i, 1] = aw * ex + ax * ew + ay * ez - az * ey
        out[i, 2] = aw * ey - ax * ez + ay * ew + az * ex
        out[i, 3] = aw * ez + ax * ey - ay * ex + az * ew


def quat_interpolate(t: ArrayLike, q: ArrayLike, t_query: ArrayLike) -> NDArray[np.float64]:
    """Attitude of a sampled rotation at other instants, by spherical linear interpolation.

    Between samples k and k + 1, ``q_k ⊗ (q_k* ⊗ q_{k+1})^s`` along the shorter arc, with
    ``s = (t_query − t_k) / (t_{k+1} − t_k)``: scipy's ``Slerp`` (same interval choice, same shorter
    arc), compiled, and without building a ``Rotation`` per interval. At a sample instant the result is
    the sample itself (negated where the arc from the previous sample turns it over, as ``Slerp`` does),
    not a product that rounds it.

    Parameters
    ----------
    t : array_like (N,)
        Sample instants, strictly increasing, N >= 2.
    q : array_like (N, 4)
        Unit quaternions at ``t``.
    t_query : array_like (M,)
        Instants within ``[t[0], t[-1]]``.

    Returns
    -------
    ndarray (M, 4)
    """
    t = np.ascontiguousarray(t, dtype=float)
    q = np.ascontiguousarray(_q(q))
    t_query = np.ascontiguousarray(t_query, dtype=float).reshape(-1)
    if t.ndim != 1 or len(t) < 2 or q.shape != (len(t), 4):
        raise ValueError(f"need N >= 2 instants and (N, 4) quaternions, got shapes {t.shape} and {q.shape}")
    if len(t_query) and (t_query.min() < t[0] or t_query.max() > t[-1]):
        raise ValueError(f"instants {t_query.min():g}..{t_query.max():g} leave the samples' span {t[0]:g}..{t[-1]:g}")
    out = np.empty((len(t_query), 4))
    _interpolate_rows(t, q, t_query, out)
    return out


@njit
def _rotate_rows(
    q: NDArray[np.float64], v: NDArray[np.float64], out: NDArray[np.float64]
) -> None:  # pragma: no cover - compiled
    for i in range(out.shape[0]):
        w, x, y, z = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
        v0, v1, v2 = v[i, 0], v[i, 1], v[i, 2]
        tx = 2.0 * (y * v2 - z * v1)  # t = 2 u × v
        ty = 2.0 * (z * v0 - x * v2)
        tz = 2.0 * (x * v1 - y * v0)
        out[i, 0] = v0 + w * tx + (y * tz - z * ty)  # v + w t + u × t
        out[i, 1] = v1 + w * ty + (z * tx - x * tz)
        out[i, 2] = v2 + w * tz + (x * ty - y * tx)


def quat_rotate(q: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
    """Rotate vectors: ``q ⊗ (0, v) ⊗ q*``, shapes ``(..., 4)`` and ``(..., 3)`` broadcast.

    Uses ``v + 2w (u × v) + 2 u × (u × v)`` with ``u`` the vector part.
    """
    a, b, out, lead = _rows(_q(q), _v(v), 3)
    _rotate_rows(a, b, out)
    return out.reshape(lead + (3,))


def quat_to_matrix(q: ArrayLike) -> NDArray[np.float64]:
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions ``(..., 4)``."""
    from scipy.spatial.transform import Rotation

    q = _q(q)
    m: NDArray[np.float64] = Rotation.from_quat(q.reshape(-1, 4), scalar_first=True).as_matrix()
    return m.reshape(q.shape[:-1] + (3, 3))


def quat_from_matrix(m: ArrayLike) -> NDArray[np.float64]:
    """Unit quaternions ``(..., 4)``, ``w >= 0``, of rotation matrices ``(..., 3, 3)``."""
    from scipy.spatial.transform import Rotation

    m = np.asarray(m, dtype=float)
    q: NDArray[np.float64] = Rotation.from_matrix(m.reshape(-1, 3, 3)).as_quat(canonical=True, scalar_first=True)
    return q.reshape(m.shape[:-2] + (4,))


def quat_from_euler_zxz(angles: ArrayLike) -> NDArray[np.float64]:
    """Quaternions of Z-X-Z angles ``(..., 3)`` = (precession φ, nutation θ, spin ψ), rad."""
    from scipy.spatial.transform import Rotation

    a = _v(angles)
    q: NDArray[np.float64] = Rotation.from_euler("ZXZ", a.reshape(-1, 3)).as_quat(scalar_first=True)
    return q.reshape(a.shape[:-1] + (4,))


def _as_euler(rotation: Rotation, seq: str) -> NDArray[np.float64]:
    """``rotation.as_euler(seq)`` without scipy's gimbal-lock warning: at the lock the split of the
    angles is a convention, documented by the callers (``suppress_warnings=`` needs scipy 1.17)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "Gimbal lock detected", UserWarning)
        angles: NDArray[np.float64] = rotation.as_euler(seq)
        return angles


def euler_zxz_from_quat(q: ArrayLike) -> NDArray[np.float64]:
    """Z-X-Z angles (φ, θ, ψ) with ``θ`` in ``[0, π]``; at ``θ = 0`` or ``π`` only φ±ψ is defined."""
    from scipy.spatial.transform import Rotation

    q = _q(q)
    a = _as_euler(Rotation.from_quat(q.reshape(-1, 4), scalar_first=True), "ZXZ")
    return a.reshape(q.shape[:-1] + (3,))


def quat_from_euler_zyx(rpy: ArrayLike) -> NDArray[np.float64]:
    """Quaternions of (roll φ, pitch θ, yaw ψ) ``(..., 3)``, rad, with ``R = Rz(ψ) Ry(θ) Rx(φ)``."""
    from scipy.spatial.transform import Rotation

    a = _v(rpy)
    q: NDArray[np.float64] = Rotation.from_euler("ZYX", a.reshape(-1, 3)[:, ::-1]).as_quat(scalar_first=True)
    return q.reshape(a.shape[:-1] + (4,))


def euler_zyx_from_quat(q: ArrayLike) -> NDArray[np.float64]:
    """(roll, pitch, yaw), rad, pitch in ``[-π/2, π/2]``, of unit quaternions."""
    from scipy.spatial.transform import Rotation

    q = _q(q)
    a = _as_euler(Rotation.from_quat(q.reshape(-1, 4), scalar_first=True), "ZYX")
    return a[:, ::-1].reshape(q.shape[:-1] + (3,))


def quat_angle(p: ArrayLike, q: ArrayLike) -> NDArray[np.float64]:
    """Angle (rad, in ``[0, π]``) of the rotation that takes ``q`` to ``p``."""
    d = quat_multiply(p, quat_conjugate(q))
    angle: NDArray[np.float64] = 2.0 * np.arctan2(np.linalg.norm(d[..., 1:], axis=-1), np.abs(d[..., 0]))
    return angle


def skew(v: ArrayLike) -> NDArray[np.float64]:
    """Cross-product matrices ``[v]×`` ``(..., 3, 3)``, so that ``skew(a) @ b == cross(a, b)``."""
    v = _v(v)
    x, y, z = np.moveaxis(v, -1, 0)
    o = np.zeros_like(x)
    return np.stack([np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)], -2)


def body_rate_from_quat_derivative(q: ArrayLike, q_dot: ArrayLike) -> NDArray[np.float64]:
    """Body angular velocity ``ω_b`` from ``q̇ = ½ q ⊗ (0, ω_b)``: ``ω_b = 2 (q* ⊗ q̇)_vec``."""
    return 2.0 * quat_multiply(quat_conjugate(q), q_dot)[..., 1:]


@overload
def body_rate_from_euler_zxz(angles: ArrayLike, rates: ArrayLike, accels: None = None) -> NDArray[np.float64]: ...


@overload
def body_rate_from_euler_zxz(
    angles: ArrayLike, rates: ArrayLike, accels: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...


def body_rate_from_euler_zxz(
    angles: ArrayLike, rates: ArrayLike, accels: ArrayLike | None = None
) -> NDArray[np.float64] | tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Body angular velocity (and acceleration) of a Z-X-Z motion.

    Parameters
    ----------
    angles, rates : array_like, shape (..., 3)
        (φ, θ, ψ) and their time derivatives, rad and rad/s.
    accels : array_like, shape (..., 3), optional
        Second derivatives, rad/s²; when given, ``α_b = dω_b/dt`` is returned too.

    Returns
    -------
    omega_b : ndarray (..., 3)
        ``[φ̇ sθ sψ + θ̇ cψ, φ̇ sθ cψ − θ̇ sψ, φ̇ cθ + ψ̇]`` for ``R = Rz(φ) Rx(θ) Rz(ψ)``.
    alpha_b : ndarray (..., 3), only when ``accels`` is given.
    """
    (_, th, p), (fd, thd, pd) = np.moveaxis(_v(angles), -1, 0), np.moveaxis(_v(rates), -1, 0)
    st, ct, sp, cp = np.sin(th), np.cos(th), np.sin(p), np.cos(p)
    omega = np.stack([fd * st * sp + thd * cp, fd * st * cp - thd * sp, fd * ct + pd], axis=-1)
    if accels is None:
        return omega
    fdd, thdd, pdd = np.moveaxis(_v(accels), -1, 0)
    alpha = np.stack(
        [
            fdd * st * sp + fd * thd * ct * sp + fd * pd * st * cp + thdd * cp - thd * pd * sp,
            fdd * st * cp + fd * thd * ct * cp - fd * pd * st * sp - thdd * sp - thd * pd * cp,
            fdd * ct - fd * thd * st + pdd,
        ],
        axis=-1,
    )
    return omega, alpha


@overload
def body_rate_from_euler_zyx(rpy: ArrayLike, rpy_rates: ArrayLike, rpy_accels: None = None) -> NDArray[np.float64]: ...


@overload
def body_rate_from_euler_zyx(
    rpy: ArrayLike, rpy_rates: ArrayLike, rpy_accels: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...


def body_rate_from_euler_zyx(
    rpy: ArrayLike, rpy_rates: ArrayLike, rpy_accels: ArrayLike | None = None
) -> NDArray[np.float64] | tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Body angular velocity (and acceleration) of a roll-pitch-yaw motion.

    Parameters
    ----------
    rpy, rpy_rates : array_like, shape (..., 3)
        (roll φ, pitch θ, yaw ψ) and their time derivatives, rad and rad/s.
    rpy_accels : array_like, shape (..., 3), optional
        Second derivatives, rad/s²; when given, ``α_b`` is returned too.

    Returns
    -------
    omega_b : ndarray (..., 3)
        ``[φ̇ − ψ̇ sθ, θ̇ cφ + ψ̇ cθ sφ, −θ̇ sφ + ψ̇ cθ cφ]`` for ``R = Rz(ψ) Ry(θ) Rx(φ)``.
    alpha_b : ndarray (..., 3), only when ``rpy_accels`` is given.
    """
    (r, th, _), (rd, thd, yd) = np.moveaxis(_v(rpy), -1, 0), np.moveaxis(_v(rpy_rates), -1, 0)
    sr, cr, st, ct = np.sin(r), np.cos(r), np.sin(th), np.cos(th)
    omega = np.stack([rd - yd * st, thd * cr + yd * ct * sr, -thd * sr + yd * ct * cr], axis=-1)
    if rpy_accels is None:
        return omega
    rdd, thdd, ydd = np.moveaxis(_v(rpy_accels), -1, 0)
    alpha = np.stack(
        [
            rdd - ydd * st - yd * thd * ct,
            thdd * cr - thd * rd * sr + ydd * ct * sr - yd * thd * st * sr + yd * rd * ct * cr,
            -thdd * sr - thd * rd * cr + ydd * ct * cr - yd * thd * st * cr - yd * rd * ct * sr,
        ],
        axis=-1,
    )
    return omega, alpha

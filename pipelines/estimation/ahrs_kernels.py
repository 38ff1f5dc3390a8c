"""The per-sample updates of the ``ahrs`` package's Madgwick, Mahony and EKF (ahrs 0.4), compiled per block.

:mod:`gyroemu.pipelines.estimation.peers` runs these filters as the library defines them; the library's
updates are per-sample Python (about 11 k samples/s). The kernels here are the same update equations,
written out term by term in the library's order of operations and compiled with numba (through
:func:`gyroemu.dynamics.jit.njit`: numba is imported on first use, not on import), one call per block
of samples. They were transcribed from the installed sources:

* ``ahrs/filters/madgwick.py``: ``Madgwick.updateIMU`` / ``updateMARG``;
* ``ahrs/filters/mahony.py``: ``Mahony.updateIMU`` / ``updateMARG`` (with the bias integral ``b``);
* ``ahrs/filters/ekf.py``: ``EKF.update`` (with ``f``, ``dfdq``, ``h``, ``dhdq`` in ``'normal'`` mode),
  and the prediction-only step the adapter makes when the accelerometer sample is missing;
* ``ahrs/common/quaternion.py``: ``Quaternion(q)`` normalises ``q`` (so Madgwick normalises its
  quaternion several times per step: in ``Quaternion(q)``, before the objective function, in
  ``Quaternion.__add__``, and at the end; Mahony's ``q += q̇ dt`` is in place, normalised once),
  ``product``, ``conj`` and ``to_DCM``.

What is kept of the library, including its corner cases: a zero gyro sample returns the (normalised)
quaternion unchanged (Madgwick, Mahony; the EKF has no such test); a zero accelerometer vector skips the
correction (Madgwick, Mahony) or returns ``q`` and ``P`` unchanged (EKF); Madgwick's and Mahony's
``updateMARG`` with a zero field falls back on ``updateIMU`` *without* ``dt`` (the nominal period); the
EKF raises on a zero field. The EKF's ``np.linalg.inv(S)`` (LAPACK ``gesv``) is an LU factorisation with
partial pivoting here. The only differences from the library are the order of a few sums (BLAS dot
products, matrix products) and that inversion: a few units in the last place per step, which the filters'
corrections keep bounded (``tests/pipelines/test_ahrs_kernels.py`` compares them with the library).

The adapter's conventions are the kernels' too: a sample with a non-finite gyro holds the estimate (and
the time of the last update, so the next step spans the gap); a non-finite or all-zero accelerometer
sample is a gyro-only step (Madgwick, Mahony: the library given zeros; EKF: prediction only); a
non-finite or all-zero magnetometer sample is a 6D update; ``dt`` is the stamp difference, or the
nominal period where that is not positive and finite. The start (the first sample's attitude) stays in
the adapter: the kernels carry a started filter's state.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyroemu.dynamics.jit import njit

__all__ = ["ekf_block", "madgwick_block", "mahony_block"]


@njit
def _usable(v: NDArray[np.float64], k: int) -> bool:
    """Row ``k`` of ``v`` is finite and not all zero (the adapter's test for a usable sample)."""
    x, y, z = v[k, 0], v[k, 1], v[k, 2]
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return False
    nonzero: bool = abs(x) + abs(y) + abs(z) > 0.0
    return nonzero


@njit
def _norm3(x: float, y: float, z: float) -> float:
    return math.sqrt(x * x + y * y + z * z)


@njit
def _norm4(w: float, x: float, y: float, z: float) -> float:
    return math.sqrt(w * w + x * x + y * y + z * z)


@njit
def _step_dt(tk: float, t_last: float, dt_nominal: float) -> float:
    dt = tk - t_last
    if not (dt > 0.0 and math.isfinite(dt)):
        dt = dt_nominal
    return dt


# --- Madgwick ----------------------------------------------------------------------------------------


@njit
def _madgwick_step(
    q: NDArray[np.float64],
    gx: float,
    gy: float,
    gz: float,
    ax: float,
    ay: float,
    az: float,
    use_a: bool,
    mx: float,
    my: float,
    mz: float,
    use_m: bool,
    dt: float,
    dt_nominal: float,
    gain: float,
) -> None:
    """``updateMARG`` (``use_m``) or ``updateIMU`` of ahrs 0.4 on ``q`` (in place). ``use_a`` False: the
    adapter's zero accelerometer vector."""
    n = _norm4(q[0], q[1], q[2], q[3])  # Quaternion(q)
    w, x, y, z = q[0] / n, q[1] / n, q[2] / n, q[3] / n
    if _norm3(gx, gy, gz) == 0.0:
        q[0], q[1], q[2], q[3] = w, x, y, z
        return
    if use_m and _norm3(mx, my, mz) == 0.0:  # updateMARG -> updateIMU(q, gyr, acc): the default dt
        use_m = False
        dt = dt_nominal
        n = _norm4(w, x, y, z)
        w, x, y, z = w / n, x / n, y / n, z / n
    # qDot = 0.5 * q.product([0, *gyr])  (eq. 12)
    dw = 0.5 * (w * 0.0 - x * gx - y * gy - z * gz)
    dx = 0.5 * (w * gx + x * 0.0 + y * gz - z * gy)
    dy = 0.5 * (w * gy - x * gz + y * 0.0 + z * gx)
    dz = 0.5 * (w * gz + x * gy - y * gx + z * 0.0)
    a_norm = _norm3(ax, ay, az) if use_a else 0.0
    if a_norm > 0.0:
        a0, a1, a2 = ax / a_norm, ay / a_norm, az / a_norm
        n = _norm4(w, x, y, z)
        qw, qx, qy, qz = w / n, x / n, y / n, z / n
        f0 = 2.0 * (qx * qz - qw * qy) - a0
        f1 = 2.0 * (qw * qx + qy * qz) - a1
        f2 = 2.0 * (0.5 - qx**2 - qy**2) - a2
        if use_m:
            m_norm = _norm3(mx, my, mz)
            m0, m1, m2 = mx / m_norm, my / m_norm, mz / m_norm
            # q_m = Quaternion([0, *m]) (normalised again); h = q ⊗ q_m ⊗ q*  (eq. 45)
            nm = _norm4(0.0, m0, m1, m2)
            pw, px, py, pz = 0.0 / nm, m0 / nm, m1 / nm, m2 / nm
            cw, cx, cy, cz = w * 1.0, x * -1.0, y * -1.0, z * -1.0
            rw = pw * cw - px * cx - py * cy - pz * cz
            rx = pw * cx + px * cw + py * cz - pz * cy
            ry = pw * cy - px * cz + py * cw + pz * cx
            rz = pw * cz + px * cy - py * cx + pz * cw
            h1 = w * rx + x * rw + y * rz - z * ry
            h2 = w * ry - x * rz + y * rw + z * rx
            h3 = w * rz + x * ry - y * rx + z * rw
            bx = math.sqrt(h1 * h1 + h2 * h2)  # (eq. 46)
            bz = h3
            f3 = 2.0 * bx * (0.5 - qy**2 - qz**2) + 2.0 * bz * (qx * qz - qw * qy) - m0
            f4 = 2.0 * bx * (qx * qy - qw * qz) + 2.0 * bz * (qw * qx + qy * qz) - m1
            f5 = 2.0 * bx * (qw * qy + qx * qz) + 2.0 * bz * (0.5 - qx**2 - qy**2) - m2
            f_norm = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2 + f3 * f3 + f4 * f4 + f5 * f5)
        else:
            f3 = f4 = f5 = 0.0
            bx = bz = 0.0
            f_norm = _norm3(f0, f1, f2)
        if f_norm > 0.0:
            # gradient = J.T @ f  (eqs. 26/32, 34)
            g0 = -2.0 * qy * f0 + 2.0 * qx * f1 + 0.0 * f2
            g1 = 2.0 * qz * f0 + 2.0 * qw * f1 + -4.0 * qx * f2
            g2 = -2.0 * qw * f0 + 2.0 * qz * f1 + -4.0 * qy * f2
            g3 = 2.0 * qx * f0 + 2.0 * qy * f1 + 0.0 * f2
            if use_m:
                g0 = g0 + (-2.0 * bz * qy) * f3 + (-2.0 * bx * qz + 2.0 * bz * qx) * f4 + (2.0 * bx * qy) * f5
                g1 = (
                    g1
                    + (2.0 * bz * qz) * f3
                    + (2.0 * bx * qy + 2.0 * bz * qw) * f4
                    + (2.0 * bx * qz - 4.0 * bz * qx) * f5
                )
                g2 = (
                    g2
                    + (-4.0 * bx * qy - 2.0 * bz * qw) * f3
                    + (2.0 * bx * qx + 2.0 * bz * qz) * f4
                    + (2.0 * bx * qw - 4.0 * bz * qy) * f5
                )
                g3 = (
                    g3
                    + (-4.0 * bx * qz + 2.0 * bz * qx) * f3
                    + (-2.0 * bx * qw + 2.0 * bz * qy) * f4
                    + (2.0 * bx * qx) * f5
                )
            g_norm = _norm4(g0, g1, g2, g3)
            g0, g1, g2, g3 = g0 / g_norm, g1 / g_norm, g2 / g_norm, g3 / g_norm
            dw -= gain * g0  # (eq. 33)
            dx -= gain * g1
            dy -= gain * g2
            dz -= gain * g3
    # q_new = q + qDot*dt (Quaternion.__add__ normalises), then q_new /= |q_new|  (eq. 13)
    w, x, y, z = w + dw * dt, x + dx * dt, y + dy * dt, z + dz * dt
    n = _norm4(w, x, y, z)
    w, x, y, z = w / n, x / n, y / n, z / n
    n = _norm4(w, x, y, z)
    q[0], q[1], q[2], q[3] = w / n, x / n, y / n, z / n


@njit
def _madgwick_loop(
    t: NDArray[np.float64],
    gyro: NDArray[np.float64],
    accel: NDArray[np.float64],
    mag: NDArray[np.float64],
    has_mag: bool,
    q: NDArray[np.float64],
    t_last: float,
    dt_nominal: float,
    gain: float,
    q_out: NDArray[np.float64],
) -> float:
    for k in range(t.shape[0]):
        if math.isfinite(gyro[k, 0]) and math.isfinite(gyro[k, 1]) and math.isfinite(gyro[k, 2]):
            dt = _step_dt(t[k], t_last, dt_nominal)
            use_a = _usable(accel, k)
            use_m = has_mag and _usable(mag, k)
            mk = k if has_mag else 0
            _madgwick_step(
                q,
                gyro[k, 0],
                gyro[k, 1],
                gyro[k, 2],
                accel[k, 0],
                accel[k, 1],
                accel[k, 2],
                use_a,
                mag[mk, 0],
                mag[mk, 1],
                mag[mk, 2],
                use_m,
                dt,
                dt_nominal,
                gain,
            )
            t_last = t[k]
        for i in range(4):
            q_out[k, i] = q[i]
    return t_last


# --- Mahony ------------------------------------------------------------------------------------------


@njit
def _mahony_step(
    q: NDArray[np.float64],
    b: NDArray[np.float64],
    gx: float,
    gy: float,
    gz: float,
    ax: float,
    ay: float,
    az: float,
    use_a: bool,
    mx: float,
    my: float,
    mz: float,
    use_m: bool,
    dt: float,
    dt_nominal: float,
    k_p: float,
    k_i: float,
) -> None:
    """``updateMARG`` (``use_m``) or ``updateIMU`` of ahrs 0.4 on ``q`` and the bias ``b`` (in place)."""
    n = _norm4(q[0], q[1], q[2], q[3])  # Quaternion(q)
    w, x, y, z = q[0] / n, q[1] / n, q[2] / n, q[3] / n
    if _norm3(gx, gy, gz) == 0.0:
        q[0], q[1], q[2], q[3] = w, x, y, z
        return
    o0, o1, o2 = gx, gy, gz
    a_norm = _norm3(ax, ay, az) if use_a else 0.0
    if a_norm > 0.0:
        if use_m and _norm3(mx, my, mz) == 0.0:  # updateMARG -> updateIMU(q, gyr, acc): the default dt
            use_m = False
            dt = dt_nominal
            n = _norm4(w, x, y, z)
            w, x, y, z = w / n, x / n, y / n, z / n
        a0, a1, a2 = ax / a_norm, ay / a_norm, az / a_norm
        # R = q.to_DCM(); v_a = R.T @ [0, 0, 1] (expected gravity) is R's last row
        r00 = 1.0 - 2.0 * (y**2 + z**2)
        r01 = 2.0 * (x * y - w * z)
        r02 = 2.0 * (x * z + w * y)
        r10 = 2.0 * (x * y + w * z)
        r11 = 1.0 - 2.0 * (x**2 + z**2)
        r12 = 2.0 * (y * z - w * x)
        r20 = 2.0 * (x * z - w * y)
        r21 = 2.0 * (w * x + y * z)
        r22 = 1.0 - 2.0 * (x**2 + y**2)
        e0 = a1 * r22 - a2 * r21  # np.cross(a, v_a)  (eqs. 32c and 48a)
        e1 = a2 * r20 - a0 * r22
        e2 = a0 * r21 - a1 * r20
        if use_m:
            m_norm = _norm3(mx, my, mz)
            m0, m1, m2 = mx / m_norm, my / m_norm, mz / m_norm
            h0 = r00 * m0 + r01 * m1 + r02 * m2  # h = R @ m
            h1 = r10 * m0 + r11 * m1 + r12 * m2
            h2 = r20 * m0 + r21 * m1 + r22 * m2
            hxy = math.sqrt(h0 * h0 + h1 * h1)
            # v_m = R.T @ [0, |h_xy|, h_z], normalised
            v0 = r00 * 0.0 + r10 * hxy + r20 * h2
            v1 = r01 * 0.0 + r11 * hxy + r21 * h2
            v2 = r02 * 0.0 + r12 * hxy + r22 * h2
            nv = _norm3(v0, v1, v2)
            v0, v1, v2 = v0 / nv, v1 / nv, v2 / nv
            e0 = e0 + (m1 * v2 - m2 * v1)
            e1 = e1 + (m2 * v0 - m0 * v2)
            e2 = e2 + (m0 * v1 - m1 * v0)
        b[0] += (-k_i * e0) * dt  # bDot = -k_I * omega_mes (eqs. 32b and 48c)
        b[1] += (-k_i * e1) * dt
        b[2] += (-k_i * e2) * dt
        o0 = o0 - b[0] + k_p * e0  # (eq. 48b)
        o1 = o1 - b[1] + k_p * e1
        o2 = o2 - b[2] + k_p * e2
    # qDot = 0.5 * q.product([0, *Omega]); q += qDot*dt (in place: not normalised); q /= |q|
    dw = 0.5 * (w * 0.0 - x * o0 - y * o1 - z * o2)
    dx = 0.5 * (w * o0 + x * 0.0 + y * o2 - z * o1)
    dy = 0.5 * (w * o1 - x * o2 + y * 0.0 + z * o0)
    dz = 0.5 * (w * o2 + x * o1 - y * o0 + z * 0.0)
    w, x, y, z = w + dw * dt, x + dx * dt, y + dy * dt, z + dz * dt
    n = _norm4(w, x, y, z)
    q[0], q[1], q[2], q[3] = w / n, x / n, y / n, z / n


@njit
def _mahony_loop(
    t: NDArray[np.float64],
    gyro: NDArray[np.float64],
    accel: NDArray[np.float64],
    mag: NDArray[np.float64],
    has_mag: bool,
    q: NDArray[np.float64],
    b: NDArray[np.float64],
    t_last: float,
    dt_nominal: float,
    k_p: float,
    k_i: float,
    q_out: NDArray[np.float64],
    b_out: NDArray[np.float64],
) -> float:
    for k in range(t.shape[0]):
        if math.isfinite(gyro[k, 0]) and math.isfinite(gyro[k, 1]) and math.isfinite(gyro[k, 2]):
            dt = _step_dt(t[k], t_last, dt_nominal)
            use_a = _usable(accel, k)
            use_m = has_mag and _usable(mag, k)
            mk = k if has_mag else 0
            _mahony_step(
                q,
                b,
                gyro[k, 0],
                gyro[k, 1],
                gyro[k, 2],
                accel[k, 0],
                accel[k, 1],
                accel[k, 2],
                use_a,
                mag[mk, 0],
                mag[mk, 1],
                mag[mk, 2],
                use_m,
                dt,
                dt_nominal,
                k_p,
                k_i,
            )
            t_last = t[k]
        for i in range(4):
            q_out[k, i] = q[i]
        for i in range(3):
            b_out[k, i] = b[i]
    return t_last


# --- EKF ---------------------------------------------------------------------------------------------


@njit
def _invert(
    s: NDArray[np.float64], m: int, inv: NDArray[np.float64], lu: NDArray[np.float64], piv: NDArray[np.int64]
) -> None:
    """``inv ← s⁻¹`` (m × m) by LU with partial pivoting (what ``np.linalg.inv``'s LAPACK ``gesv`` does)."""
    for i in range(m):
        for j in range(m):
            lu[i, j] = s[i, j]
        piv[i] = i
    for j in range(m):
        p = j
        big = abs(lu[j, j])
        for i in range(j + 1, m):
            if abs(lu[i, j]) > big:
                big = abs(lu[i, j])
                p = i
        if p != j:
            for c in range(m):
                lu[j, c], lu[p, c] = lu[p, c], lu[j, c]
            piv[j], piv[p] = piv[p], piv[j]
        d = lu[j, j]
        if d == 0.0:
            raise ValueError("Singular matrix")
        for i in range(j + 1, m):
            lu[i, j] /= d
            f = lu[i, j]
            for c in range(j + 1, m):
                lu[i, c] -= f * lu[j, c]
    for col in range(m):
        for i in range(m):  # forward: L y = P e_col
            acc = 1.0 if piv[i] == col else 0.0
            for c in range(i):
                acc -= lu[i, c] * inv[c, col]
            inv[i, col] = acc
        for i in range(m - 1, -1, -1):  # back: U x = y
            acc = inv[i, col]
            for c in range(i + 1, m):
                acc -= lu[i, c] * inv[c, col]
            inv[i, col] = acc / lu[i, i]


@njit
def _ekf_predict(
    q: NDArray[np.float64],
    gx: float,
    gy: float,
    gz: float,
    dt: float,
    p: NDArray[np.float64],
    g_noise: float,
    q_t: NDArray[np.float64],
    f: NDArray[np.float64],
    wm: NDArray[np.float64],
    tmp: NDArray[np.float64],
) -> None:
    """q_t = f(q, ω, dt); P ← F P Fᵀ + g_noise W Wᵀ (in place). Returns nothing; ``f`` holds F."""
    hd = 0.5 * dt
    # F = dfdq(ω, dt) = I + Ω(0.5 dt ω), the same matrix as f's I + 0.5 dt Ω(ω)
    f[0, 0], f[0, 1], f[0, 2], f[0, 3] = 1.0, -(hd * gx), -(hd * gy), -(hd * gz)
    f[1, 0], f[1, 1], f[1, 2], f[1, 3] = hd * gx, 1.0, hd * gz, -(hd * gy)
    f[2, 0], f[2, 1], f[2, 2], f[2, 3] = hd * gy, -(hd * gz), 1.0, hd * gx
    f[3, 0], f[3, 1], f[3, 2], f[3, 3] = hd * gz, hd * gy, -(hd * gx), 1.0
    for i in range(4):
        s = 0.0
        for j in range(4):
            s += f[i, j] * q[j]
        q_t[i] = s
    # W = 0.5 dt [[-q_v], [q_w I + [q_v]×]]
    qw, qx, qy, qz = q[0], q[1], q[2], q[3]
    wm[0, 0], wm[0, 1], wm[0, 2] = hd * -qx, hd * -qy, hd * -qz
    wm[1, 0], wm[1, 1], wm[1, 2] = hd * qw, hd * -qz, hd * qy
    wm[2, 0], wm[2, 1], wm[2, 2] = hd * qz, hd * qw, hd * -qx
    wm[3, 0], wm[3, 1], wm[3, 2] = hd * -qy, hd * qx, hd * qw
    for i in range(4):  # tmp = F P
        for j in range(4):
            s = 0.0
            for c in range(4):
                s += f[i, c] * p[c, j]
            tmp[i, j] = s
    for i in range(4):  # P_t = (F P) Fᵀ + (g_noise W) Wᵀ
        for j in range(4):
            s = 0.0
            for c in range(4):
                s += tmp[i, c] * f[j, c]
            qn = 0.0
            for c in range(3):
                qn += (g_noise * wm[i, c]) * wm[j, c]
            p[i, j] = s + qn


@njit
def _ekf_loop(
    t: NDArray[np.float64],
    gyro: NDArray[np.float64],
    acc: NDArray[np.float64],
    mag: NDArray[np.float64],
    has_mag: bool,
    q: NDArray[np.float64],
    p: NDArray[np.float64],
    t_last: float,
    dt_nominal: float,
    a_ref: NDArray[np.float64],
    m_ref: NDArray[np.float64],
    g_noise: float,
    a_noise: float,
    m_noise: float,
    q_out: NDArray[np.float64],
) -> float:
    q_t = np.empty(4)
    f = np.empty((4, 4))
    wm = np.empty((4, 3))
    tmp = np.empty((4, 4))
    h = np.empty((6, 4))
    v = np.empty(6)
    ph = np.empty((4, 6))
    hp = np.empty((6, 4))
    s = np.empty((6, 6))
    s_inv = np.empty((6, 6))
    lu = np.empty((6, 6))
    piv = np.empty(6, dtype=np.int64)
    k_gain = np.empty((4, 6))
    ikh = np.empty((4, 4))
    ref = np.empty(6)
    for i in range(3):
        ref[i] = a_ref[i]
        ref[3 + i] = m_ref[i]
    for k in range(t.shape[0]):
        if math.isfinite(gyro[k, 0]) and math.isfinite(gyro[k, 1]) and math.isfinite(gyro[k, 2]):
            dt = _step_dt(t[k], t_last, dt_nominal)
            gx, gy, gz = gyro[k, 0], gyro[k, 1], gyro[k, 2]
            if not _usable(acc, k):
                # The adapter's prediction-only step (the library would return q unchanged).
                _ekf_predict(q, gx, gy, gz, dt, p, g_noise, q_t, f, wm, tmp)
                n = _norm4(q_t[0], q_t[1], q_t[2], q_t[3])
                for i in range(4):
                    q[i] = q_t[i] / n
            else:
                ax, ay, az = acc[k, 0], acc[k, 1], acc[k, 2]
                a_norm = _norm3(ax, ay, az)
                if a_norm == 0.0:  # the library returns q (and keeps P)
                    pass
                else:
                    use_m = has_mag and _usable(mag, k)
                    m = 6 if use_m else 3
                    v[0], v[1], v[2] = ax / a_norm, ay / a_norm, az / a_norm  # z, then v = z - y
                    if use_m:
                        mx, my, mz = mag[k, 0], mag[k, 1], mag[k, 2]
                        m_norm = _norm3(mx, my, mz)
                        if m_norm == 0.0:
                            raise ValueError("Invalid geomagnetic field. Its magnitude must be greater than zero.")
                        v[3], v[4], v[5] = mx / m_norm, my / m_norm, mz / m_norm
                    _ekf_predict(q, gx, gy, gz, dt, p, g_noise, q_t, f, wm, tmp)  # p holds P_t
                    # y = h(q_t): C = DCM(q_t / |q_t|)ᵀ; y = C a_ref (, C m_ref)
                    n = _norm4(q_t[0], q_t[1], q_t[2], q_t[3])
                    w, x, y, z = q_t[0] / n, q_t[1] / n, q_t[2] / n, q_t[3] / n
                    c00 = 1.0 - 2.0 * (y**2 + z**2)
                    c10 = 2.0 * (x * y - w * z)
                    c20 = 2.0 * (x * z + w * y)
                    c01 = 2.0 * (x * y + w * z)
                    c11 = 1.0 - 2.0 * (x**2 + z**2)
                    c21 = 2.0 * (y * z - w * x)
                    c02 = 2.0 * (x * z - w * y)
                    c12 = 2.0 * (w * x + y * z)
                    c22 = 1.0 - 2.0 * (x**2 + y**2)
                    for blk in range(m // 3):
                        r0, r1, r2 = ref[3 * blk], ref[3 * blk + 1], ref[3 * blk + 2]
                        v[3 * blk] -= c00 * r0 + c01 * r1 + c02 * r2
                        v[3 * blk + 1] -= c10 * r0 + c11 * r1 + c12 * r2
                        v[3 * blk + 2] -= c20 * r0 + c21 * r1 + c22 * r2
                        # H = dhdq(q_t) ('normal' mode, on the unnormalised q_t), times 2
                        qw, qx, qy, qz = q_t[0], q_t[1], q_t[2], q_t[3]
                        o = 3 * blk
                        h[o, 0] = 2.0 * (r0 * qw + r1 * qz - r2 * qy)
                        h[o, 1] = 2.0 * (r0 * qx + r1 * qy + r2 * qz)
                        h[o, 2] = 2.0 * (-r0 * qy + r1 * qx - r2 * qw)
                        h[o, 3] = 2.0 * (-r0 * qz + r1 * qw + r2 * qx)
                        h[o + 1, 0] = 2.0 * (-r0 * qz + r1 * qw + r2 * qx)
                        h[o + 1, 1] = 2.0 * (r0 * qy - r1 * qx + r2 * qw)
                        h[o + 1, 2] = 2.0 * (r0 * qx + r1 * qy + r2 * qz)
                        h[o + 1, 3] = 2.0 * (-r0 * qw - r1 * qz + r2 * qy)
                        h[o + 2, 0] = 2.0 * (r0 * qy - r1 * qx + r2 * qw)
                        h[o + 2, 1] = 2.0 * (r0 * qz - r1 * qw - r2 * qx)
                        h[o + 2, 2] = 2.0 * (r0 * qw + r1 * qz - r2 * qy)
                        h[o + 2, 3] = 2.0 * (r0 * qx + r1 * qy + r2 * qz)
                    for i in range(4):  # ph = P_t Hᵀ
                        for j in range(m):
                            acc_ = 0.0
                            for c in range(4):
                                acc_ += p[i, c] * h[j, c]
                            ph[i, j] = acc_
                    for i in range(m):  # hp = H P_t
                        for j in range(4):
                            acc_ = 0.0
                            for c in range(4):
                                acc_ += h[i, c] * p[c, j]
                            hp[i, j] = acc_
                    for i in range(m):  # S = (H P_t) Hᵀ + R
                        for j in range(m):
                            acc_ = 0.0
                            for c in range(4):
                                acc_ += hp[i, c] * h[j, c]
                            if i == j:
                                acc_ += a_noise if i < 3 else m_noise
                            s[i, j] = acc_
                    _invert(s, m, s_inv, lu, piv)
                    for i in range(4):  # K = (P_t Hᵀ) S⁻¹
                        for j in range(m):
                            acc_ = 0.0
                            for c in range(m):
                                acc_ += ph[i, c] * s_inv[c, j]
                            k_gain[i, j] = acc_
                    for i in range(4):  # I - K H
                        for j in range(4):
                            acc_ = 0.0
                            for c in range(m):
                                acc_ += k_gain[i, c] * h[c, j]
                            ikh[i, j] = (1.0 if i == j else 0.0) - acc_
                    for i in range(4):  # P = (I - K H) P_t
                        for j in range(4):
                            acc_ = 0.0
                            for c in range(4):
                                acc_ += ikh[i, c] * p[c, j]
                            tmp[i, j] = acc_
                    for i in range(4):
                        for j in range(4):
                            p[i, j] = tmp[i, j]
                    for i in range(4):  # q = q_t + K v, normalised
                        acc_ = 0.0
                        for c in range(m):
                            acc_ += k_gain[i, c] * v[c]
                        q_t[i] = q_t[i] + acc_
                    n = _norm4(q_t[0], q_t[1], q_t[2], q_t[3])
                    for i in range(4):
                        q[i] = q_t[i] / n
            t_last = t[k]
        for i in range(4):
            q_out[k, i] = q[i]
    return t_last


# --- Block interfaces --------------------------------------------------------------------------------


def _block_inputs(
    t: ArrayLike, gyro: ArrayLike, accel: ArrayLike, mag: ArrayLike | None
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], bool]:
    t = np.ascontiguousarray(t, dtype=np.float64).reshape(-1)
    gyro = np.ascontiguousarray(gyro, dtype=np.float64).reshape(-1, 3)
    accel = np.ascontiguousarray(accel, dtype=np.float64).reshape(-1, 3)
    if mag is None:
        return t, gyro, accel, np.zeros((1, 3)), False
    return t, gyro, accel, np.ascontiguousarray(mag, dtype=np.float64).reshape(-1, 3), True


def madgwick_block(
    t: ArrayLike,
    gyro: ArrayLike,
    accel: ArrayLike,
    mag: ArrayLike | None,
    q: NDArray[np.float64],
    t_last: float,
    dt_nominal: float,
    gain: float,
) -> tuple[NDArray[np.float64], float]:
    """Madgwick (ahrs 0.4) over a block of samples from the started state ``q`` (library frame, NWU; updated
    in place) and ``t_last`` (stamp of the last update). ``mag`` None: 6D (``updateIMU``). Returns the
    per-sample quaternions (n, 4) and the new ``t_last``."""
    t, gyro, accel, mag, has_mag = _block_inputs(t, gyro, accel, mag)
    q_out = np.empty((len(t), 4))
    t_last = _madgwick_loop(t, gyro, accel, mag, has_mag, q, float(t_last), float(dt_nominal), float(gain), q_out)
    return q_out, float(t_last)


def mahony_block(
    t: ArrayLike,
    gyro: ArrayLike,
    accel: ArrayLike,
    mag: ArrayLike | None,
    q: NDArray[np.float64],
    b: NDArray[np.float64],
    t_last: float,
    dt_nominal: float,
    k_p: float,
    k_i: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Mahony (ahrs 0.4) over a block from the started state ``q`` (library frame, ENU) and bias integral
    ``b`` (both updated in place). Returns the per-sample quaternions (n, 4), biases (n, 3) and ``t_last``."""
    t, gyro, accel, mag, has_mag = _block_inputs(t, gyro, accel, mag)
    q_out = np.empty((len(t), 4))
    b_out = np.empty((len(t), 3))
    t_last = _mahony_loop(
        t, gyro, accel, mag, has_mag, q, b, float(t_last), float(dt_nominal), float(k_p), float(k_i), q_out, b_out
    )
    return q_out, b_out, float(t_last)


def ekf_block(
    t: ArrayLike,
    gyro: ArrayLike,
    acc: ArrayLike,
    mag: ArrayLike | None,
    q: NDArray[np.float64],
    p: NDArray[np.float64],
    t_last: float,
    dt_nominal: float,
    a_ref: ArrayLike,
    m_ref: ArrayLike,
    noises: tuple[float, float, float],
) -> tuple[NDArray[np.float64], float]:
    """The ahrs 0.4 EKF (``update``, and prediction only for a missing accelerometer sample) over a block
    from the started state ``q`` (library frame) and covariance ``p`` (4 × 4), both updated in place.
    ``acc`` is what the library is given (the adapter's ``−accel``), ``mag`` None a 6D filter; ``a_ref``,
    ``m_ref`` and ``noises`` (gyro, accelerometer, magnetometer variances) the library object's. Returns
    the per-sample quaternions (n, 4) and ``t_last``."""
    t, gyro, acc, mag, has_mag = _block_inputs(t, gyro, acc, mag)
    q_out = np.empty((len(t), 4))
    g_noise, a_noise, m_noise = (float(x) for x in noises)
    t_last = _ekf_loop(
        t,
        gyro,
        acc,
        mag,
        has_mag,
        q,
        p,
        float(t_last),
        float(dt_nominal),
        np.asarray(a_ref, dtype=np.float64),
        np.asarray(m_ref, dtype=np.float64),
        g_noise,
        a_noise,
        m_noise,
        q_out,
    )
    return q_out, float(t_last)

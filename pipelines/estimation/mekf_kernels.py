"""The compiled parts of the MEKF that both its forms share: the per-sample strapdown and the
measurement models. :mod:`gyroemu.pipelines.estimation.mekf` wraps them with filterpy's Kalman algebra;
:mod:`gyroemu.pipelines.estimation.batched` with its own, run across many runs at once.

The error state (``δθ``, ``δb``, ``δM``)
---------------------------------------
``δθ`` is the attitude error in world axes, ``R_true = (I + [δθ×]) R_est`` (``q_true = δq ⊗ q_est``).
The gyro reads ``ω_m = (I + M) ω + b + n``: ``M`` holds the scale-factor errors (diagonal) and the
misalignments (off the diagonal), the strapdown integrates ``(I − M̂)(ω_m − b̂)``, and ``δb = b − b̂``,
``δM = M − M̂`` (body axes; nine states, row-major) are their errors, so that to first order the
integrated rate is wrong by ``δb + δM u`` (``u = ω_m − b̂``). Between samples (Titterton & Weston
§12.3.1, in the world frame; Earth rate ``Ω_ie`` when the latitude is known):

    δθ̇ = −[Ω_ie×] δθ − R_est (δb + δM u) − R_est n_g,        δḃ = n_b,        δṀ = n_M

The strapdown runs at every sample; the covariance is propagated once per *window* (a few tens of
milliseconds) with the transition ``Φ = [[I − [Ω_ie×] T, Φ_θb, Φ_θM], [0, I, 0], [0, 0, I]]``,
``Φ_θb = −Σ R_k Δt_k`` and ``Φ_θM`` likewise, accumulated over the window's samples, which is what a
strapdown INS does (the attitude at full rate, the error model at a lower one). The rotation makes
``δM`` observable: each turn shows its own scale factor and what leaks into the other axes.

Measurements, made at the end of each window
--------------------------------------------
* Gravity direction: the specific force turned into the world frame with the current estimate and
  low-passed twice, ``ā_w`` (filtering in the world frame removes vibration and translation without
  lagging rotation, the idea of VQF's inertial-frame low-pass filter). With ``u = ā_w/|ā_w|``, at rest
  ``u = e_z + e_z × δθ``: ``(u_x, u_y) = (−δθ_y, δθ_x)``, whatever the heading. The low-passes hold
  forces turned with past attitudes, so they see the error as it was: ``δθ + D (δb, δM)``, ``D`` the
  drift since, weighted by the low-pass (2τ R for a steady drift), tracked per sample. What the
  low-passes keep of a non-gravitational acceleration slower than they are adds ``a/g``: the error state
  carries it as ``δa`` (world x, y; a first-order Gauss–Markov process, a consider state:
  :func:`gravity_update`), and whatever
  acceleration the innovations show beyond the model goes into the measurement's noise
  (:func:`gravity_adapt`, innovation-based adaptive estimation).
* Heading: the magnetic field turned into the world frame and averaged, ``m̄_w``; its azimuth from
  north is ``ψ = atan2(m_x, m_y) = D + δθ_z + tan(dip) (n · δθ)`` (``D`` the declination, ``n`` the
  field's horizontal direction).
* Rest: the mean gyro over a window at rest is the bias plus Earth's rate,
  ``ω̄_m − R_estᵀ Ω_ie − b_est = δb + R_estᵀ [Ω_ie×] δθ``; with a precise gyro and a known latitude the
  second term finds north (gyrocompassing), otherwise it sharpens the bias.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from gyroemu.dynamics.jit import njit
from gyroemu.dynamics.rotation import half_turn, rotate_body, set_product

# Window accumulator layout (one float64 vector per filter).
W_ACC_N = 0  # valid accelerometer samples in the window
W_MAG = 1  # 1:4  Σ R m_b over valid magnetometer samples, T
W_MAG_N = 4
W_T = 5  # window duration so far, s
W_N = 6  # samples in the window
W_EXTRA = 7  # extra attitude variance accrued (held samples, scale-factor uncertainty), rad²
W_REST_G = 8  # 8:11 Σ ω_m over the window's samples at rest, rad/s
W_REST_N = 11
W_MAG_T = 12  # time the heading window has run, s
W_SIZE = 13

# Slow state layout (one float64 vector per filter).
S_T = 0  # last stamp, s
S_OMEGA = 1  # 1:4 last valid gyro sample, rad/s
S_LP_G = 4  # 4:7 low-passed gyro, rad/s
S_LP_A = 7  # 7:10 low-passed specific force, m/s²
S_REST_T = 10  # time at rest so far, s
S_MAG_NORM = 11  # reference field: norm, T
S_MAG_DIP = 12  # and dip (angle below the horizontal), rad
S_MAG_REJ_T = 13  # time since the last accepted heading update, s
S_GRAVITY = 14  # gravity magnitude seen at initialisation, m/s²
S_GRAV_LP = 15  # 15:18 specific force in the world frame, low-passed once, m/s²
S_GRAV_LP2 = 18  # 18:21 and twice: the gravity measurement, m/s²
S_LAG1 = 21  # 21:57 D₁ (3×12, row-major): the first low-pass's sensitivity to δb and δM
S_LAG2 = 57  # 57:93 D₂: the second's (the measurement's); see strapdown and gravity_measurement
S_SCALE = 93  # 93:102 M̂ (3×3, row-major): the gyro's scale-factor and misalignment errors
S_ACC_MS = 102  # mean square of the gravity innovation per horizontal axis, low-passed over accel_tau_s, rad²
S_ACC_CORR = 103  # the current gravity measurement's correlation factor 4τ/T (gravity_measurement)
S_ACC_EST = 104  # 104:106 â: the low-passed horizontal non-gravitational acceleration over g, world x and y, rad
S_REST_N = 106  # gyro samples in the accepted rest windows of the current stretch at rest
S_REST_SUM = 107  # 107:110 their sum of ω_m, rad/s
S_SIZE = 110

# Error state layout.
X_THETA = 0  # 0:3 δθ, rad, world axes
X_BIAS = 3  # 3:6 δb, rad/s, body axes
X_SCALE = 6  # 6:15 δM (3×3, row-major), dimensionless
X_ACC = 15  # 15:17 δa: error of â (S_ACC_EST), the low-passed horizontal acceleration over g, rad
X_SIZE = 17
N_DRIFT = X_ACC - X_BIAS  # the error states that drive the attitude error: δb and δM


@njit
def quat_to_matrix(q: NDArray[np.float64], r: NDArray[np.float64]) -> None:
    """R (3, 3) of the unit quaternion q = (w, x, y, z), written into ``r``."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    r[0, 0] = 1 - 2 * (y * y + z * z)
    r[0, 1] = 2 * (x * y - w * z)
    r[0, 2] = 2 * (x * z + w * y)
    r[1, 0] = 2 * (x * y + w * z)
    r[1, 1] = 1 - 2 * (x * x + z * z)
    r[1, 2] = 2 * (y * z - w * x)
    r[2, 0] = 2 * (x * z - w * y)
    r[2, 1] = 2 * (y * z + w * x)
    r[2, 2] = 1 - 2 * (x * x + y * y)


@njit
def strapdown(
    q: NDArray[np.float64],
    b: NDArray[np.float64],
    slow: NDArray[np.float64],
    win: NDArray[np.float64],
    phi: NDArray[np.float64],
    t: NDArray[np.float64],
    gyro: NDArray[np.float64],
    delta_angle: NDArray[np.float64],
    accel: NDArray[np.float64],
    mag: NDArray[np.float64],
    earth_rate_w: NDArray[np.float64],
    params: NDArray[np.float64],
    start: int,
    q_out: NDArray[np.float64],
) -> int:
    """Advance the filter from sample ``start`` until a window closes or the samples end.

    ``t`` (n,) s; ``gyro`` (n, 3) rad/s, or ``delta_angle`` (n, 3) rad when it has rows (then
    ``gyro`` is ignored); ``accel`` (n, 3) m/s²; ``mag`` (n, 3) T (NaN rows: none). ``q``, ``b``,
    ``slow``, ``win``, ``phi`` (3, N_DRIFT: the window's Φ_θb, Φ_θM) are updated in place and
    ``q_out[k]`` receives the attitude after sample k. Returns the index after the last sample consumed;
    the window is due for its updates when it has run ``params[P_WINDOW]`` seconds or
    ``params[P_WINDOW_N]`` samples (see :func:`window_due`). Raises ``ValueError`` on a stamp that does not increase.
    """
    n = len(t)
    r = np.empty((3, 3))
    quat_to_matrix(q, r)  # the attitude before each sample; recomputed once per sample, after its rotation
    inc = np.empty((3, N_DRIFT))  # this sample's −ΔΦ: how δb and δM turn the attitude over it
    u = np.empty(3)
    w = np.empty(3)
    use_delta = delta_angle.shape[0] > 0
    turn_noise2 = params[P_TURN_NOISE] ** 2
    hold_rate = params[P_HOLD_RATE]
    alpha_tau = params[P_REST_TAU]
    rest_g, rest_a, rest_w = params[P_REST_GYRO], params[P_REST_ACCEL], params[P_REST_RATE]
    use_mag = params[P_USE_MAG] > 0.5
    k = start
    while k < n:
        dt = t[k] - slow[S_T]
        if not dt > 0.0:
            raise ValueError("sample stamps must increase")
        slow[S_T] = t[k]
        # The rate over [t_{k-1}, t_k], bias, scale and misalignment and Earth rate removed:
        # ω_bw = (I − M̂)(ω_m − b̂) − Rᵀ Ω_ie.
        if use_delta:
            w[0], w[1], w[2] = delta_angle[k, 0] / dt, delta_angle[k, 1] / dt, delta_angle[k, 2] / dt
        else:
            w[0], w[1], w[2] = gyro[k, 0], gyro[k, 1], gyro[k, 2]
        valid = math.isfinite(w[0]) and math.isfinite(w[1]) and math.isfinite(w[2])
        for i in range(3):
            if valid:
                slow[S_OMEGA + i] = w[i]
            u[i] = slow[S_OMEGA + i] - b[i]  # a missing sample holds the last valid rate
        for i in range(3):
            e = r[0, i] * earth_rate_w[0] + r[1, i] * earth_rate_w[1] + r[2, i] * earth_rate_w[2]
            m0 = S_SCALE + 3 * i
            w[i] = u[i] - (slow[m0] * u[0] + slow[m0 + 1] * u[1] + slow[m0 + 2] * u[2]) - e
        wx, wy, wz = w[0], w[1], w[2]
        turned = math.sqrt(wx * wx + wy * wy + wz * wz) * dt
        if not valid:  # a held sample: its increment is uncertain by up to a hold_rate·dt rotation
            win[W_EXTRA] += (max(turned / dt, hold_rate) * dt) ** 2
        # What the scale-factor states cannot hold (nonlinearity, a scale that changes with the rate,
        # stamps off by a little) turns every rotation by a fraction σ of itself; as a random walk in
        # the turned angle (variance σ² per radian) it does not vanish with the step size.
        win[W_EXTRA] += turn_noise2 * turned
        # The rate error δb + δM u turns the attitude by −R (δb + δM u) Δt: Φ_θb = −Σ R Δt, and for
        # δM_ac (axis a's error per rad/s about c) the column −Σ R[:, a] u_c Δt.
        for i in range(3):
            for a in range(3):
                inc[i, a] = r[i, a] * dt
                for c in range(3):
                    inc[i, 3 + 3 * a + c] = r[i, a] * u[c] * dt
            for j in range(N_DRIFT):
                phi[i, j] -= inc[i, j]
        rotate_body(q, wx * dt, wy * dt, wz * dt)
        quat_to_matrix(q, r)

        # Rest detector (VQF's idea): samples stay close to their low-pass, and the bias-corrected
        # rate is small.
        alpha = dt / (alpha_tau + dt)
        still = valid
        dev_g = 0.0
        dev_a = 0.0
        lp_rate = 0.0
        for i in range(3):
            g_i = slow[S_OMEGA + i]
            slow[S_LP_G + i] += alpha * (g_i - slow[S_LP_G + i])
            dev_g += (g_i - slow[S_LP_G + i]) ** 2
            lp_rate += (slow[S_LP_G + i] - b[i]) ** 2
            if math.isfinite(accel[k, i]):
                slow[S_LP_A + i] += alpha * (accel[k, i] - slow[S_LP_A + i])
                dev_a += (accel[k, i] - slow[S_LP_A + i]) ** 2
            else:
                still = False
        still = still and dev_g < rest_g * rest_g and lp_rate < rest_w * rest_w and dev_a < rest_a * rest_a
        if still:
            slow[S_REST_T] += dt
            for i in range(3):
                win[W_REST_G + i] += slow[S_OMEGA + i]
            win[W_REST_N] += 1.0
        else:
            slow[S_REST_T] = 0.0
            slow[S_REST_N : S_REST_SUM + 3] = 0.0
            win[W_REST_G : W_REST_N + 1] = 0.0

        # Gravity and field in the world frame, summed over the window.
        # The specific force in the world frame through two first-order low-passes in cascade,
        # H(s) = 1/(1 + τs)², exact for any step (α = 1 − e^(−Δt/τ)): its 1/f² roll-off removes
        # back-and-forth translation far better than a mean over a window, whose 1/f does not.
        ax, ay, az = accel[k, 0], accel[k, 1], accel[k, 2]
        accel_valid = math.isfinite(ax) and math.isfinite(ay) and math.isfinite(az)
        alpha_g = 1.0 - math.exp(-dt / params[P_ACC_TAU]) if accel_valid else 0.0
        if accel_valid:
            for i in range(3):
                a_w = r[i, 0] * ax + r[i, 1] * ay + r[i, 2] * az
                slow[S_GRAV_LP + i] += alpha_g * (a_w - slow[S_GRAV_LP + i])
                slow[S_GRAV_LP2 + i] += alpha_g * (slow[S_GRAV_LP + i] - slow[S_GRAV_LP2 + i])
            win[W_ACC_N] += 1.0
        # What the low-passes hold was turned with past attitudes, whose errors differ from today's by
        # the drift since: δθ(t') = δθ(t) + ∫_{t'}^{t} R (δb + δM u) du. Each stage's output is thus
        # δθ + D (δb, δM), with D₁ ← (1 − α)(D₁ + inc), D₂ ← (1 − α)(D₂ + inc) + α D₁ (for a steady
        # drift, D₂ → 2τ R: the cascade's group delay).
        for e in range(3 * N_DRIFT):
            i, j = e // N_DRIFT, e % N_DRIFT
            d1 = (1.0 - alpha_g) * (slow[S_LAG1 + e] + inc[i, j])
            slow[S_LAG2 + e] = (1.0 - alpha_g) * (slow[S_LAG2 + e] + inc[i, j]) + alpha_g * d1
            slow[S_LAG1 + e] = d1
        if use_mag:
            mx, my, mz = mag[k, 0], mag[k, 1], mag[k, 2]
            if math.isfinite(mx) and math.isfinite(my) and math.isfinite(mz):
                for i in range(3):
                    win[W_MAG + i] += r[i, 0] * mx + r[i, 1] * my + r[i, 2] * mz
                win[W_MAG_N] += 1.0
        win[W_T] += dt
        win[W_N] += 1.0
        win[W_MAG_T] += dt
        q_out[k, :] = q
        k += 1
        if window_due(win, params):
            break
    return k


@njit
def body_vertical(q: NDArray[np.float64]) -> tuple[float, float, float]:
    """The world's vertical in body axes, ``Rᵀ e_z`` (the third row of R), of the unit quaternion q = (w, x, y, z)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)


@njit
def window_due(win: NDArray[np.float64], params: NDArray[np.float64]) -> bool:
    """Whether the window has run its time or its sample count."""
    due: bool = win[W_T] >= params[P_WINDOW] or win[W_N] >= params[P_WINDOW_N]
    return due


# Parameter vector layout (see MekfParams for meanings and units).
P_WINDOW = 0
P_WINDOW_N = 1
P_GYRO_NOISE = 2
P_BIAS_RW = 3
P_SCALE_RW = 4
P_HOLD_RATE = 5
P_ACC_NOISE = 6
P_MOTION = 7
P_MOTION_GAIN = 8
P_ACC_GATE = 9  # accel_gate: gravity_adapt's threshold, a χ²(2) quantile
P_HEADING_SIGMA = 10
P_MAG_NOISE = 11
P_MAG_NORM_TOL = 12
P_MAG_DIP_TOL = 13
P_MAG_GATE = 14
P_MAG_TIMEOUT = 15
P_REST_TAU = 16
P_REST_GYRO = 17
P_REST_ACCEL = 18
P_REST_TIME = 19
P_REST_SIGMA = 20
P_USE_MAG = 21
P_DECLINATION = 22
P_ACC_TAU = 23
P_MAG_WINDOW = 24
P_HEADING_CORR = 25
P_TURN_NOISE = 26
P_HEADING_MOTION = 27
P_ACC_ADAPT = 28
P_ACC_GM_PROCESS = 29
P_ACC_GM_TAU = 30
P_REST_RATE = 31
P_REST_GATE = 32
P_ACC_RISE = 33
P_BIAS_RW_VERTICAL = 34
P_SIZE = 35


@njit
def transition(
    win: NDArray[np.float64],
    phi: NDArray[np.float64],
    q: NDArray[np.float64],
    earth_rate_w: NDArray[np.float64],
    params: NDArray[np.float64],
    F: NDArray[np.float64],
    Q: NDArray[np.float64],
) -> None:
    """The window's transition ``F`` and process noise ``Q`` (X_SIZE, X_SIZE), written in place; ``q`` the
    attitude (w, x, y, z) at the window's end, whose body vertical splits the bias's random walk."""
    T = win[W_T]
    F[:, :] = 0.0
    Q[:, :] = 0.0
    for i in range(X_SIZE):
        F[i, i] = 1.0
    # I − [Ω_ie×] T
    F[0, 1] += earth_rate_w[2] * T
    F[0, 2] -= earth_rate_w[1] * T
    F[1, 0] -= earth_rate_w[2] * T
    F[1, 2] += earth_rate_w[0] * T
    F[2, 0] += earth_rate_w[1] * T
    F[2, 1] -= earth_rate_w[0] * T
    F[0:3, X_BIAS : X_BIAS + N_DRIFT] = phi
    # The low-passed horizontal acceleration (over g) as a first-order Gauss–Markov process of τ_a
    # (Gelb, Applied Optimal Estimation, 1974, §4.4: coloured measurement noise as a state):
    # δa_k+1 = e^(−T/τ_a) δa_k + w, var w = σ_p² (1 − e^(−2T/τ_a)), σ_p its stationary level
    # (MekfParams.accel_gm_process_sigma; its prior, what the first samples took in, is set apart).
    decay = math.exp(-T / params[P_ACC_GM_TAU])
    q_acc = params[P_ACC_GM_PROCESS] ** 2 * (1.0 - decay * decay)
    for i in range(2):
        F[X_ACC + i, X_ACC + i] = decay
        Q[X_ACC + i, X_ACC + i] = q_acc
    q_att = params[P_GYRO_NOISE] ** 2 * T + win[W_EXTRA]
    q_bias = params[P_BIAS_RW] ** 2 * T
    q_scale = params[P_SCALE_RW] ** 2 * T
    # The bias's random walk split along the body vertical v = Rᵀ e_z: q_h (I − v vᵀ) + q_v v vᵀ
    # (MekfParams.gyro_bias_random_walk_vertical: only the field and rests see the vertical bias).
    vertical = body_vertical(q)
    q_vertical = params[P_BIAS_RW_VERTICAL] ** 2 * T - q_bias
    for i in range(3):
        Q[X_THETA + i, X_THETA + i] = q_att
        Q[X_BIAS + i, X_BIAS + i] = q_bias
    for i in range(3):
        for j in range(3):
            Q[X_BIAS + i, X_BIAS + j] += q_vertical * vertical[i] * vertical[j]
    for i in range(X_SCALE, X_SCALE + 9):  # δM only: δa's noise is q_acc (until 2026-11-26 overwritten)
        Q[i, i] = q_scale


@njit
def double_lowpass_variance(density: float, tau: float) -> float:
    """Variance of white noise of density ``density`` (N) through two first-order low-passes of ``tau``
    in cascade, ``1/(1 + τs)²``, as the gravity measurement's force goes through them (:func:`strapdown`):

        σ² = N² ∫₀^∞ h(t)² dt = N² / (4τ),    h(t) = t e^(−t/τ) / τ²

    N is the project's density (:mod:`gyroemu.sensors.noise`, the Allan convention: a per-sample σ of
    N/√Δt, a two-sided PSD of N²), so the output's variance is N² times the integral of the squared
    impulse response: ∫ t² e^(−2t/τ) dt = τ³/4, over τ⁴. (N²/(8τ), which stood here until 2026-11-27,
    takes N² for the one-sided PSD: half the variance.)"""
    return density * density / (4.0 * tau)


@njit
def gravity_measurement(
    win: NDArray[np.float64],
    slow: NDArray[np.float64],
    params: NDArray[np.float64],
    z: NDArray[np.float64],
    H: NDArray[np.float64],
    R: NDArray[np.float64],
) -> bool:
    """The gravity-direction measurement at the end of a window: ``z`` (2,), ``H`` (2, X_SIZE), ``R`` (2, 2).

    ``z`` is the horizontal part of the direction of the low-passed world-frame specific force
    ``ā_w`` (:func:`strapdown`). Returns False when the window had no valid accelerometer sample.

    Noise. White noise of density N through ``1/(1 + τs)²`` has the variance ``N² / (4τ)``
    (:func:`double_lowpass_variance`); that of the sensor and the non-gravitational acceleration
    always allowed for (both densities) is the base. What the low-pass left of the motion shows in
    ``|ā_w| − g`` (the vertical share of the residual, as large as each horizontal one for motion
    in every direction), weighted by ``motion_gain``. All over g², in rad². The output's
    autocorrelation integrates to N² (the cascade's DC gain is 1), ``4τ`` times its variance, so a
    measurement every window of T carries the information of ``T / 4τ`` independent ones: ``R`` is
    scaled by ``4τ / T`` (the white part then N²/T, the variance of the noise's mean over T)."""
    decay = math.exp(-win[W_T] / params[P_ACC_GM_TAU])  # â's expected value decays as the process does
    slow[S_ACC_EST] *= decay
    slow[S_ACC_EST + 1] *= decay
    n = win[W_ACC_N]
    win[W_ACC_N] = 0.0
    if n < 1.0:
        return False
    ax, ay, az = slow[S_GRAV_LP2], slow[S_GRAV_LP2 + 1], slow[S_GRAV_LP2 + 2]
    norm = math.sqrt(ax * ax + ay * ay + az * az)
    if not norm > 0.0:
        return False
    g = slow[S_GRAVITY]
    # the horizontal acceleration the low-passes hold adds a/g to the direction: u = (−y_y, y_x) + a/g
    z[0] = ax / norm - slow[S_ACC_EST]
    z[1] = ay / norm - slow[S_ACC_EST + 1]
    H[:, :] = 0.0
    H[0, X_ACC] = 1.0
    H[1, X_ACC + 1] = 1.0
    # u_x = −y_y, u_y = y_x with y = δθ + D₂ (δb, δM) (strapdown): the tilt as the low-pass saw it
    H[0, 1] = -1.0
    H[1, 0] = 1.0
    for j in range(N_DRIFT):
        H[0, X_BIAS + j] = -slow[S_LAG2 + N_DRIFT + j]
        H[1, X_BIAS + j] = slow[S_LAG2 + j]
    tau = params[P_ACC_TAU]
    white = double_lowpass_variance(params[P_ACC_NOISE], tau) + double_lowpass_variance(params[P_MOTION], tau)
    var = (white + params[P_MOTION_GAIN] * (norm - g) ** 2) / (g * g)
    corr = 4.0 * tau / max(win[W_T], 1e-9)
    slow[S_ACC_CORR] = corr
    var *= corr
    R[:, :] = 0.0
    R[0, 0] = var
    R[1, 1] = var
    return True


@njit
def heading_measurement(
    win: NDArray[np.float64], slow: NDArray[np.float64], params: NDArray[np.float64]
) -> tuple[bool, float, float, float, float]:
    """The heading measurement, when its window (``mag_window_s``) is complete: ``(ok, y, r, h_x, h_y)``
    with the innovation ``y = ψ − D`` (rad, wrapped), its variance ``r`` and the tilt columns of its
    ``H = (h_x, h_y, 1, 0, …, 0)``; the window's sums are then cleared. Not ok while the window is
    open, when it had no field, or when the field is disturbed: its norm or dip differ from the
    reference by more than the tolerances.

    The field is turned into the world frame with the whole estimated attitude, so a tilt error
    leaks into the heading: with ``m̂_w = (I − [δθ×]) m_w``, ``ψ̂ = ψ + δθ_z + tan(dip) (n · δθ)``,
    ``n`` the field's horizontal direction. The update never corrects tilt (:func:`heading_gain`), but
    ``S`` counts the tilt's uncertainty and the innovation the tilt already corrected."""
    T = win[W_MAG_T]
    n = win[W_MAG_N]
    if T < params[P_MAG_WINDOW]:
        return False, 0.0, 0.0, 0.0, 0.0
    mx, my, mz = win[W_MAG] / max(n, 1.0), win[W_MAG + 1] / max(n, 1.0), win[W_MAG + 2] / max(n, 1.0)
    win[W_MAG : W_MAG_N + 1] = 0.0
    win[W_MAG_T] = 0.0
    if n < 1.0:
        return False, 0.0, 0.0, 0.0, 0.0
    horizontal = math.sqrt(mx * mx + my * my)
    norm = math.sqrt(horizontal * horizontal + mz * mz)
    if not horizontal > 0.0:
        return False, 0.0, 0.0, 0.0, 0.0
    dip = math.atan2(-mz, horizontal)
    ref_norm, ref_dip = slow[S_MAG_NORM], slow[S_MAG_DIP]
    if abs(norm - ref_norm) > params[P_MAG_NORM_TOL] * ref_norm or abs(dip - ref_dip) > params[P_MAG_DIP_TOL]:
        return False, 0.0, 0.0, 0.0, 0.0
    y = math.atan2(mx, my) - params[P_DECLINATION]
    y = (y + math.pi) % (2.0 * math.pi) - math.pi
    # The field's heading error (residual soft iron, local anomalies) is correlated over
    # heading_correlation_s: a window of T carries T / τ_c of an independent measurement of it.
    r = params[P_HEADING_SIGMA] ** 2 * max(params[P_HEADING_CORR] / T, 1.0) + params[P_MAG_NOISE] ** 2 / T / (
        horizontal * horizontal
    )
    if slow[S_REST_T] < T:  # moved during the window: the field where the body moves may differ from at rest
        r *= params[P_HEADING_MOTION]
    tan_dip = -mz / horizontal
    return True, y, r, tan_dip * mx / horizontal, tan_dip * my / horizontal


@njit
def heading_gain(
    P: NDArray[np.float64], h: NDArray[np.float64], r: float, q: NDArray[np.float64], K: NDArray[np.float64]
) -> float:
    """Kalman gain ``K`` (X_SIZE,) of the heading measurement ``H = hᵀ`` (:func:`heading_measurement`),
    constrained so that it never corrects inclination: the ``δθ_x``, ``δθ_y`` rows are zero, and the
    bias correction is kept to the body's vertical axis ``v = Rᵀ e_z`` (the only bias the heading
    sees). Nor does it touch ``δM``: the heading sees only ``vᵀ δM ω``, and a field disturbance that
    passed the gates would be learnt into the scale factors and carried into every later turn (on
    BROAD's magnet trial 31 it cost 1.3° of heading); the gravity direction, seen through turns about
    every axis, teaches ``δM``. Returns ``S = H P Hᵀ + r``."""
    Ph = P @ h
    hPh: Any = h @ Ph  # a scalar (1-D @ 1-D), which numpy's stubs type as an array
    S: float = hPh + r
    for i in range(X_SIZE):
        K[i] = Ph[i] / S
    K[0] = 0.0
    K[1] = 0.0
    v0, v1, v2 = body_vertical(q)
    along = K[X_BIAS] * v0 + K[X_BIAS + 1] * v1 + K[X_BIAS + 2] * v2
    K[X_BIAS], K[X_BIAS + 1], K[X_BIAS + 2] = along * v0, along * v1, along * v2
    K[X_SCALE:] = 0.0  # nor δM, nor the acceleration (a gravity-channel state, like the tilt)
    return S


@njit
def joseph_update(P: NDArray[np.float64], K: NDArray[np.float64], h: NDArray[np.float64], r: float) -> None:
    """P ← (I − K hᵀ) P (I − K hᵀ)ᵀ + K r Kᵀ for a scalar measurement ``H = hᵀ``: valid for any gain,
    optimal or not."""
    A = np.eye(len(K)) - np.outer(K, h)
    P[:, :] = A @ P @ A.T + r * np.outer(K, K)


@njit
def rest_measurement(
    win: NDArray[np.float64],
    q: NDArray[np.float64],
    b: NDArray[np.float64],
    earth_rate_w: NDArray[np.float64],
    params: NDArray[np.float64],
    z: NDArray[np.float64],
    H: NDArray[np.float64],
    R: NDArray[np.float64],
    P: NDArray[np.float64],
) -> None:
    """The rest measurement: ``z = ω̄_m − Rᵀ Ω_ie − b`` (3,), ``H = [Rᵀ [Ω_ie×], I, 0]`` (3, X_SIZE),
    ``R`` (3, 3): white noise over the window's rest samples plus the residual-rate floor (at rest
    the scale and misalignment errors turn nothing, δM ω ≈ 0), plus what the linear ``H`` leaves out
    of the Earth rate's turn: ``Rᵀ (I + [δθ×] + ½[δθ×]²) Ω``, whose second-order term is up to
    ``½ |δθ|² |Ω|``, with ``E|δθ|² = tr P_θθ`` (``P`` the prior covariance; a heading known to tens of
    degrees only, as after a short gyrocompass, would otherwise be read as tilt)."""
    n = win[W_REST_N]
    r = np.empty((3, 3))
    quat_to_matrix(q, r)
    H[:, :] = 0.0
    ex, ey, ez = earth_rate_w[0], earth_rate_w[1], earth_rate_w[2]
    # [Ω×] = [[0, −ez, ey], [ez, 0, −ex], [−ey, ex, 0]];  H_θ = Rᵀ [Ω×]
    cross = np.array([[0.0, -ez, ey], [ez, 0.0, -ex], [-ey, ex, 0.0]])
    H[:, 0:3] = r.T @ cross
    for i in range(3):
        e = r[0, i] * ex + r[1, i] * ey + r[2, i] * ez
        z[i] = win[W_REST_G + i] / n - e - b[i]
        H[i, X_BIAS + i] = 1.0
    dt_mean = win[W_T] / max(win[W_N], 1.0)
    var = params[P_GYRO_NOISE] ** 2 / (n * dt_mean) + params[P_REST_SIGMA] ** 2
    omega = math.sqrt(ex * ex + ey * ey + ez * ez)
    var += (0.5 * (P[0, 0] + P[1, 1] + P[2, 2]) * omega) ** 2
    R[:, :] = 0.0
    for i in range(3):
        R[i, i] = var


@njit
def gravity_adapt(
    P: NDArray[np.float64],
    z: NDArray[np.float64],
    H: NDArray[np.float64],
    R: NDArray[np.float64],
    slow: NDArray[np.float64],
    params: NDArray[np.float64],
) -> None:
    """Match the gravity measurement's ``R`` to what the innovations show (``x = 0``, as it is the first
    after the prediction; ``R`` is modified in place).

    The low-passed force keeps whatever non-gravitational acceleration lasts longer than the low-pass (a
    car speeding up for seconds, a slow sway, a tap's swing): an error the filter does not estimate,
    coloured, and far larger than the white density allows for while it lasts. Innovation-based adaptive
    estimation (Mehra 1970; Mohamed & Schwarz 1999, J. Geodesy 73: ``R̂ = Ĉ − H P Hᵀ``, ``Ĉ`` the
    innovations' sample covariance; Suh 2010, IEEE TIM 59(12), for an orientation filter under external
    acceleration): ``Ĉ`` per horizontal axis is the mean of ``|z|²/2`` low-passed over ``accel_tau_s``
    (``x = 0``, so ``z`` is the innovation), and what it holds beyond the single measurement's expected
    variance ``tr(H P Hᵀ)/2 + R T/(4τ)`` is the unmodelled acceleration's variance (over g²), added to
    ``R`` with the same correlation factor ``4τ/T``, once it is significant: ``2 Ĉ`` beyond ``accel_gate``
    (a χ²(2) quantile) times the expected variance without the slow acceleration ``δa`` (Suh's threshold;
    a lower one, the 95 % quantile, took the smooth manoeuvre's sway for acceleration and doubled its 6D
    inclination error). ``Ĉ`` rises over ``accel_adapt_rise_s`` and falls over ``4τ``. Weight
    ``accel_adapt`` (0: off).

    Every measurement is then taken: a χ² gate on ``zᵀ (H P Hᵀ + R)⁻¹ z`` stood here until 2026-11-27,
    but with ``R`` scaled by ``4τ/T`` (about 200) it never fired (docs/offline-attitude.md)."""
    adapt = params[P_ACC_ADAPT]
    if not adapt > 0.0:
        return
    HPH = H @ P @ H.T
    corr = slow[S_ACC_CORR]  # 4τ/T
    window = params[P_ACC_TAU] * 4.0 / corr  # T, s
    # The mean square follows a rise over accel_adapt_rise_s (faster than the filter's tilt takes an
    # acceleration in) and a fall over 4τ: an acceleration that ends leaves the cascade's output as
    # t e^(−t/τ), which takes about 4τ to vanish.
    square = 0.5 * (z[0] * z[0] + z[1] * z[1])
    rise = square > slow[S_ACC_MS]
    beta = 1.0 - math.exp(-window / (params[P_ACC_RISE] if rise else 4.0 * params[P_ACC_TAU]))
    slow[S_ACC_MS] += beta * (square - slow[S_ACC_MS])
    expected = 0.5 * (HPH[0, 0] + HPH[1, 1]) + 0.5 * (R[0, 0] + R[1, 1]) / corr
    # Suh's threshold: only a significant excess counts (the mean square holds about one independent
    # innovation, so below a χ² quantile it is noise and max(·, 0) would bias R upwards). The threshold
    # scales with the spread of that estimate, the innovation's fast part: without the slow acceleration
    # δa, whose variance stays the same over the mean square's time (notes of issue #17: with δa in it,
    # the attitude NEES of the car × tactical MEMS left its band on other seeds).
    Hw = H.copy()
    Hw[:, X_ACC:] = 0.0
    HPHw = Hw @ P @ Hw.T
    fast = 0.5 * (HPHw[0, 0] + HPHw[1, 1]) + 0.5 * (R[0, 0] + R[1, 1]) / corr
    excess = 0.0
    if 2.0 * slow[S_ACC_MS] > params[P_ACC_GATE] * fast:
        excess = adapt * max(slow[S_ACC_MS] - expected, 0.0) * corr
    R[0, 0] += excess
    R[1, 1] += excess


@njit
def gravity_update(
    x: NDArray[np.float64],
    P: NDArray[np.float64],
    z: NDArray[np.float64],
    H: NDArray[np.float64],
    R: NDArray[np.float64],
) -> None:
    """The gravity measurement's Kalman update, ``x`` (X_SIZE,) and ``P`` in place, with the acceleration
    ``δa`` a *consider* state (the Schmidt–Kalman filter: Schmidt, "Application of state-space methods to
    navigation problems", Advances in Control Systems 3, 1966): its rows of the gain are zero, so the
    filter never estimates the acceleration (an estimate would outlast an acceleration that has ended by
    ``accel_gm_tau_s``: on the car drive it doubled the tilt error), but the covariance carries its
    correlation with the tilt, Joseph form (valid for any gain)."""
    PHT = P @ H.T
    S = H @ PHT + R
    K = PHT @ np.linalg.inv(S)
    K[X_ACC:, :] = 0.0
    x += K @ (z - H @ x)
    A = np.eye(X_SIZE) - K @ H
    P[:, :] = A @ P @ A.T + K @ R @ K.T


@njit
def rest_gate(win: NDArray[np.float64], slow: NDArray[np.float64], params: NDArray[np.float64]) -> bool:
    """Whether the window's mean rate at rest is the stretch's (then it joins the stretch's mean).

    The detector calls rest whatever turns more slowly than its thresholds: a car cruising straight is at
    rest for the gyro (correctly: it reads its bias and Earth's rate), but so is the first second of a
    turn, whose rate ramps up through the thresholds; taken as bias, it turned the heading by 0.5° in a
    second. At rest the rate is stationary: a window whose mean rate ``ω̄_w`` leaves the mean of the
    stretch's accepted windows ``ω̄_s`` by more than white noise allows, ``|ω̄_w − ω̄_s|² / (N²/(n_w Δt) +
    N²/(n_s Δt))`` beyond the gate ``rest_gate`` (``MekfParams.rest_gate``), is rotation and rejected. The test does not
    use the filter's bias, so a bias the filter has wrong is still learnt (a gate on the innovation
    ``z − H x`` kept only the windows that agreed with it). The first window of a stretch is accepted."""
    n = win[W_REST_N]
    dt_mean = win[W_T] / max(win[W_N], 1.0)
    n_s = slow[S_REST_N]
    ok = True
    if n_s > 0.0:
        d2 = 0.0
        for i in range(3):
            d = win[W_REST_G + i] / n - slow[S_REST_SUM + i] / n_s
            d2 += d * d
        var = params[P_GYRO_NOISE] ** 2 / dt_mean * (1.0 / n + 1.0 / n_s)
        ok = d2 <= params[P_REST_GATE] * var
    if ok:
        slow[S_REST_N] += n
        for i in range(3):
            slow[S_REST_SUM + i] += win[W_REST_G + i]
    return ok


@njit
def heading_update(
    x: NDArray[np.float64],
    P: NDArray[np.float64],
    q: NDArray[np.float64],
    win: NDArray[np.float64],
    slow: NDArray[np.float64],
    params: NDArray[np.float64],
) -> bool:
    """The heading measurement, gated, applied with the constrained gain of :func:`heading_gain`
    (Joseph form): ``x`` (X_SIZE,) and ``P`` are updated in place. Returns whether it was applied."""
    T = win[W_MAG_T]
    ok, y, r, h_x, h_y = heading_measurement(win, slow, params)
    if not ok:
        slow[S_MAG_REJ_T] += T if T >= params[P_MAG_WINDOW] else 0.0
        return False
    h = np.zeros(X_SIZE)
    h[0], h[1], h[2] = h_x, h_y, 1.0
    y -= h @ x
    K = np.empty(X_SIZE)
    S = heading_gain(P, h, r, q, K)
    if y * y / S > params[P_MAG_GATE]:
        slow[S_MAG_REJ_T] += T
        if slow[S_MAG_REJ_T] <= params[P_MAG_TIMEOUT]:
            return False
        r *= y * y / S / params[P_MAG_GATE]
        S = heading_gain(P, h, r, q, K)
    else:
        slow[S_MAG_REJ_T] = 0.0
    for i in range(X_SIZE):
        x[i] += K[i] * y
    joseph_update(P, K, h, r)
    return True


@njit
def rest_due(win: NDArray[np.float64], slow: NDArray[np.float64], params: NDArray[np.float64]) -> bool:
    """Whether the window ends a stretch at rest long enough for the rest measurement."""
    due: bool = slow[S_REST_T] >= params[P_REST_TIME] and win[W_REST_N] >= 1.0
    return due


@njit
def inject(
    x: NDArray[np.float64],
    q: NDArray[np.float64],
    b: NDArray[np.float64],
    slow: NDArray[np.float64],
    win: NDArray[np.float64],
    phi: NDArray[np.float64],
) -> None:
    """Fold the error estimate into the nominal state (``q ← exp(δθ) ⊗ q``, ``b ← b + δb``,
    ``M̂ ← M̂ + δM``), zero it, and open a new window."""
    turn = np.empty(4)
    turn[0], turn[1], turn[2], turn[3] = half_turn(x[0], x[1], x[2])  # exp(δθ/2), world axes
    set_product(q, turn[0], turn[1], turn[2], turn[3], q[0], q[1], q[2], q[3])
    # The low-passed specific force was turned into the world frame with past estimates: turn it by
    # the correction those would have had, δθ + D (δb, δM) (strapdown), so that the measurement does
    # not see the error it already gave.
    c = np.empty((3, 3))
    past = np.empty(3)
    for s0, d0 in ((S_GRAV_LP, S_LAG1), (S_GRAV_LP2, S_LAG2)):
        for i in range(3):
            past[i] = x[X_THETA + i]
            for j in range(N_DRIFT):
                past[i] += slow[d0 + N_DRIFT * i + j] * x[X_BIAS + j]
        turn[0], turn[1], turn[2], turn[3] = half_turn(past[0], past[1], past[2])
        quat_to_matrix(turn, c)
        v0, v1, v2 = slow[s0], slow[s0 + 1], slow[s0 + 2]
        for i in range(3):
            slow[s0 + i] = c[i, 0] * v0 + c[i, 1] * v1 + c[i, 2] * v2
    for i in range(3):
        b[i] += x[X_BIAS + i]
    for e in range(9):
        slow[S_SCALE + e] += x[X_SCALE + e]
    slow[S_ACC_EST] += x[X_ACC]
    slow[S_ACC_EST + 1] += x[X_ACC + 1]
    # â is a world-frame vector held in the estimated axes: a heading correction turns it as it turns the force
    turn[0], turn[1], turn[2], turn[3] = half_turn(x[0], x[1], x[2])
    quat_to_matrix(turn, c)
    v0, v1 = slow[S_ACC_EST], slow[S_ACC_EST + 1]
    slow[S_ACC_EST] = c[0, 0] * v0 + c[0, 1] * v1
    slow[S_ACC_EST + 1] = c[1, 0] * v0 + c[1, 1] * v1
    x[:] = 0.0
    for i in (W_T, W_N, W_EXTRA, W_REST_G, W_REST_G + 1, W_REST_G + 2, W_REST_N):
        win[i] = 0.0
    phi[:, :] = 0.0


@njit
def rotations_since_first(t: NDArray[np.float64], gyro: NDArray[np.float64]) -> NDArray[np.float64]:
    """``R_0k`` (n, 3, 3): the rotation from sample k's body axes to sample 0's, integrated from the
    gyro (NaN samples count as zero rate), for averaging the first samples in one frame."""
    n = len(t)
    out = np.empty((n, 3, 3))
    q = np.array([1.0, 0.0, 0.0, 0.0])
    quat_to_matrix(q, out[0])
    for k in range(1, n):
        dt = t[k] - t[k - 1]
        w = np.empty(3)
        for i in range(3):
            w[i] = gyro[k, i] * dt if math.isfinite(gyro[k, i]) else 0.0
        rotate_body(q, w[0], w[1], w[2])
        quat_to_matrix(q, out[k])
    return out

"""Well-known attitude filters behind gyroemu's filter protocol: Madgwick, Mahony and the EKF of the
``ahrs`` package, and VQF from the ``vqf`` package (an optional extra: ``pip install 'gyroemu[vqf]'``).

Each adapter is made from a :class:`~gyroemu.pipelines.estimation.protocol.FilterSetup`, keeps the library's
state from one ``process()`` block to the next, and returns ``q_wb`` in gyroemu's convention (ENU world,
body to world, scalar first). Each library's defaults are kept; what the adapter has to decide (frames,
initialisation, time steps, missing samples) is listed here.

Frames, found on BROAD trial 02 (``tests/pipelines/test_bench.py`` checks them on simulated truth)
-------------------------------------------------------------------------------------------------
All four libraries integrate ``q̇ = ½ q ⊗ (0, ω)``: their quaternion turns body vectors into their
world frame, scalar first, like gyroemu's. Their world frames differ:

=============  ======================================================  ===========================
library        world frame (with the accelerometer as it is: +g up)    to ENU
=============  ======================================================  ===========================
Madgwick       x magnetic north, z up (so y west: NWU)                  ``q_z(+90°) ⊗ q``
Mahony         x east, y magnetic north, z up (ENU)                     ``q``
ahrs EKF       NED, but it takes the accelerometer as the gravity       ``C ⊗ q``, ``C`` the NED↔ENU
               vector (down): the adapter feeds it ``−accel``           swap, ``(0, 1, 1, 0)/√2``
VQF            ENU, y magnetic north (9D); heading arbitrary (6D)       ``q``
=============  ======================================================  ===========================

(The EKF fed the accelerometer as it is mixes an up-gravity with a down-dipping field reference:
21.9° inclination RMSE on trial 02 against 0.97° with ``−accel``; its ``frame='ENU'`` option is
inconsistent the other way round.) A 9D estimate is then turned from magnetic north to true north by
the site's declination, ``q_wb = q_z(−declination) ⊗ q`` (``FilterSetup.declination_rad``: 0 for a
foreign log such as BROAD, whose reference frame is magnetic). A 6D estimate's heading is arbitrary
and left as it is.

The ``ahrs`` update equations, compiled
--------------------------------------
The updates of Madgwick, Mahony and the EKF are ahrs 0.4's (``updateIMU``/``updateMARG``, ``update``),
but their per-sample Python ran at about 11 k samples/s; the adapters run them instead through
:mod:`.ahrs_kernels`, the same equations written out in the library's order of operations and compiled
with numba, one call per block (1 to 8 M samples/s). The start below stays in Python, and the library's
filter object is still made: its parameters (gain, ``k_P``, ``k_I``, references, noises) are read from
it, and its state (Mahony's ``b``, the EKF's ``P``) is carried in it. Setting ``_reference`` on an
adapter runs the library's own per-sample updates instead; ``tests/pipelines/test_ahrs_kernels.py``
cross-checks the two on simulated motion, on missing samples and blocks, and on BROAD trial 02: they
agree to round-off (at most 26 ε, 424 ε in the 6D EKF's unobservable heading).

Defaults kept, by library
-------------------------
- Madgwick (ahrs 0.4): gain β = 0.033 (6D, ``gain_imu``) and 0.041 (9D, ``gain_marg``), rad/s, from
  Madgwick's report. No bias state.
- Mahony (ahrs 0.4): ``k_P`` = 1.0, ``k_I`` = 0.3, bias starting at 0; its integral term is the gyro
  bias estimate (``Estimate.gyro_bias``).
- ahrs EKF: state ``q`` only (no bias), ``P0 = I₄``, spectral variances gyro 0.3², accelerometer 0.5²,
  magnetometer 0.8² (of the normalised vectors). Its magnetic reference defaults to Munich's WMM
  field; the adapter gives it the dip angle measured in the first sample instead,
  ``asin(−â·m̂)`` (69.2° at the start of BROAD trial 02, 2.3° total RMSE there against 5.7° with Munich's).
- VQF (vqf 2.x): :class:`vqf.VQF` (the online filter, not ``offlineVQF``), default parameters (τ_acc
  3 s, τ_mag 9 s, rest and motion bias estimation, magnetic disturbance rejection), fed block by block
  through ``updateBatch`` so its state carries over. ``Estimate.gyro_bias`` is its bias estimate.

Initialisation, time steps, units, missing samples
-------------------------------------------------
- The ``ahrs`` filters start, as their own batch mode does (``Q[0]`` from ``acc2q``/``ecompass``), from
  the first sample: the adapter computes that attitude itself (TRIAD on gravity and the field in 9D,
  the smallest tilt in 6D), in the library's frame (the library's ``ecompass(frame='NED')`` start
  contradicts Madgwick's NWU update). The output for that sample is the initial attitude; each later
  sample is one library update. VQF initialises itself (its accelerometer low-pass starts on the first
  sample, its heading converges fast at first, ``magNewFirstTime``).
- The ``ahrs`` updates take their own ``dt``: the adapter passes the stamp difference
  ``t_k − t_{k−1}`` (uneven spacing and gaps as recorded), or the nominal ``1/rate_hz`` of the setup
  where that difference is not positive and finite. VQF runs at the fixed ``1/rate_hz`` (it has no
  per-sample step).
- Magnetometer units: the ahrs docs ask for nT (Madgwick, EKF) or µT (Mahony), VQF for any unit;
  every one of them only uses the field's direction (VQF's disturbance tests are relative), so the
  adapters pass µT.
- A sample with a non-finite gyro holds the last estimate (the next sample's ``dt`` spans the gap);
  a non-finite accelerometer sample propagates the gyro only; a non-finite magnetometer sample in 9D
  is a 6D update (so a slower magnetometer, NaN between its samples, works; the start takes the
  block's first field sample). Before the first usable sample the output is NaN.
"""

from __future__ import annotations

import math
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyroemu.dynamics.rotation import quat_conjugate, quat_from_matrix, quat_from_rotvec, quat_multiply, skew

from .ahrs_kernels import ekf_block, madgwick_block, mahony_block
from .protocol import Estimate, FilterSetup

__all__ = ["AhrsEkf", "Madgwick", "Mahony", "OfflineVqf", "Vqf", "VqfUnavailable", "import_vqf", "initial_attitude"]

_SQRT_HALF = math.sqrt(0.5)
_Q_NWU_TO_ENU = np.array([_SQRT_HALF, 0.0, 0.0, _SQRT_HALF])  # q_z(+90°): NWU coordinates to ENU
_Q_NED_TO_ENU = np.array([0.0, _SQRT_HALF, _SQRT_HALF, 0.0])  # (x, y, z)_NED -> (y, x, -z)
_Q_IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


class VqfUnavailable(ImportError):
    """The optional ``vqf`` package is not installed."""


def _unit(v: np.ndarray) -> np.ndarray | None:
    n = float(np.linalg.norm(v))
    return v / n if n > 0 and math.isfinite(n) else None


def initial_attitude(accel: np.ndarray, mag: np.ndarray | None = None) -> np.ndarray | None:
    """``q_wb`` (w, x, y, z) of one sample at rest: ENU with y along magnetic north (TRIAD on the
    specific force, which points up, and the field) when ``mag`` is given, else the smallest tilt that
    brings the specific force to +z. None when the vectors are unusable (zero, non-finite, parallel)."""
    up = _unit(np.asarray(accel, dtype=float))
    if up is None:
        return None
    if mag is None:
        # Smallest rotation taking `up` (body) to z (world): axis up × z, angle acos(up·z).
        w = 1.0 + up[2]
        if w < 1e-9:  # upside down: half a turn about x
            return np.array([0.0, 1.0, 0.0, 0.0])
        q: NDArray[np.float64] = np.array([w, up[1], -up[0], 0.0])  # (1 + c, up × z) normalised
        return q / np.linalg.norm(q)
    m = np.asarray(mag, dtype=float)
    east = _unit(np.cross(m, up))
    if east is None:
        return None
    north = np.cross(up, east)
    return quat_from_matrix(np.array([east, north, up]))  # rows: world axes in body coordinates


def _as_inputs(
    t: ArrayLike, gyro: ArrayLike, accel: ArrayLike, mag: ArrayLike | None, use_mag: bool
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None]:
    t = np.asarray(t, dtype=float).reshape(-1)
    gyro = np.asarray(gyro, dtype=float).reshape(-1, 3)
    accel = np.asarray(accel, dtype=float).reshape(-1, 3)
    if not len(t) == len(gyro) == len(accel):
        raise ValueError(f"t, gyro and accel must have the same length, got {len(t)}, {len(gyro)}, {len(accel)}")
    if use_mag and mag is not None:
        mag = np.asarray(mag, dtype=float).reshape(-1, 3)
        if len(mag) != len(t):
            raise ValueError(f"mag must have the length of t ({len(t)}), got {len(mag)}")
        mag = mag * 1e6  # tesla -> µT (only the direction matters to these filters)
    else:
        mag = None
    return t, gyro, accel, mag


class _AhrsPeer:
    """The loop shared by the ``ahrs`` filters: the start in Python, then the block through the compiled
    kernel of the library's update (:mod:`.ahrs_kernels`), or, with ``_reference`` set, through the
    library's own per-sample updates (the kernels' reference, for the tests)."""

    name = ""
    has_bias = False
    _to_enu = _Q_IDENTITY  # library world frame -> ENU (magnetic)
    _reference = False  # True: the library's per-sample Python updates instead of the compiled kernels
    _f: Any  # the library's filter object (made by _start)

    def __init__(self, setup: FilterSetup):
        self.setup = setup
        self.period = 1.0 / float(setup.rate_hz)
        self._q: np.ndarray | None = None  # the library's quaternion (its own frame)
        self._t_last: float | None = None  # stamp of the last sample the filter took
        self._out_rot = quat_from_rotvec([0.0, 0.0, -setup.declination_rad]) if setup.use_mag else _Q_IDENTITY

    # The library-specific parts.
    def _start(self, q_lib: np.ndarray, accel: np.ndarray, mag: np.ndarray | None) -> None:
        """Make the library's filter object, starting at ``q_lib``."""

    def _step(
        self,
        q: NDArray[np.float64],
        gyro: NDArray[np.float64],
        accel: NDArray[np.float64] | None,
        mag: NDArray[np.float64] | None,
        dt: float,
    ) -> NDArray[np.float64]:
        """One library update (``accel`` or ``mag`` None: not usable in this sample). Madgwick's and
        Mahony's share their API: ``updateMARG`` with a field, ``updateIMU`` without."""
        if accel is None:
            accel = np.zeros(3)  # the library skips the correction for a zero vector
        q_new: NDArray[np.float64]
        if mag is not None:
            q_new = self._f.updateMARG(q, gyr=gyro, acc=accel, mag=mag, dt=dt)
            return q_new
        q_new = self._f.updateIMU(q, gyr=gyro, acc=accel, dt=dt)
        return q_new

    def _block(
        self,
        t: NDArray[np.float64],
        gyro: NDArray[np.float64],
        accel: NDArray[np.float64],
        mag: NDArray[np.float64] | None,
        q_out: NDArray[np.float64],
        b_out: NDArray[np.float64] | None,
    ) -> None:
        """The compiled kernel over a block of a started filter: fills ``q_out`` (and ``b_out``), carries
        ``self._q``, ``self._t_last`` and the library object's state (bias, covariance)."""
        raise NotImplementedError

    def _bias(self) -> np.ndarray:
        return np.full(3, np.nan)

    def process(self, t: ArrayLike, gyro: ArrayLike, accel: ArrayLike, mag: ArrayLike | None = None) -> Estimate:
        t, gyro, accel, mag = _as_inputs(t, gyro, accel, mag, self.setup.use_mag)
        n = len(t)
        q_out = np.full((n, 4), np.nan)
        b_out = np.full((n, 3), np.nan) if self.has_bias else None
        finite_g = cast(NDArray[np.bool_], np.isfinite(gyro).all(axis=1))  # numpy's stubs: a bool or an array
        finite_a = np.isfinite(accel).all(axis=1) & (np.abs(accel).sum(axis=1) > 0)
        # None exactly when mag is None (the loop tests it in mag's stead)
        finite_m = None if mag is None else np.isfinite(mag).all(axis=1) & (np.abs(mag).sum(axis=1) > 0)
        dt_nominal = self.period
        for k in range(n):
            if self._q is None:
                if not (finite_g[k] and finite_a[k]):
                    continue  # not started: NaN
                # The field of this sample, or of the block's next one that has it (a slower magnetometer).
                later = None if finite_m is None else np.flatnonzero(finite_m[k:])
                # (mag is not None where finite_m is not)
                m0 = cast(NDArray[np.float64], mag)[k + later[0]] if later is not None and len(later) else None
                q0 = initial_attitude(accel[k], m0)
                if q0 is None:
                    continue
                self._q = quat_multiply(quat_conjugate(self._to_enu), q0)
                self._start(self._q, accel[k], m0)
                self._t_last = t[k]
            elif not self._reference:  # started: the rest of the block through the compiled kernel
                self._q = np.array(self._q, dtype=float)
                self._block(
                    t[k:],
                    gyro[k:],
                    accel[k:],
                    None if mag is None else mag[k:],
                    q_out[k:],
                    None if b_out is None else b_out[k:],
                )
                break
            elif finite_g[k]:
                dt = t[k] - self._t_last
                if not (dt > 0 and math.isfinite(dt)):
                    dt = dt_nominal
                self._q = np.asarray(
                    self._step(
                        self._q,
                        gyro[k],
                        accel[k] if finite_a[k] else None,
                        cast(NDArray[np.float64], mag)[k] if finite_m is not None and finite_m[k] else None,
                        dt,
                    ),
                    dtype=float,
                )
                self._t_last = t[k]
            # (a missing gyro sample holds the last estimate)
            q_out[k] = self._q
            if b_out is not None:
                b_out[k] = self._bias()
        q_wb = quat_multiply(self._out_rot, quat_multiply(self._to_enu, q_out))
        return Estimate(q_wb=q_wb, gyro_bias=b_out)


class Madgwick(_AhrsPeer):
    """Madgwick's gradient-descent filter (``ahrs.filters.Madgwick``), default gains (β 0.033 / 0.041)."""

    name = "madgwick"
    _to_enu = _Q_NWU_TO_ENU

    def _start(self, q_lib: NDArray[np.float64], accel: NDArray[np.float64], mag: NDArray[np.float64] | None) -> None:
        from ahrs.filters import Madgwick as _Madgwick

        self._f = _Madgwick(frequency=self.setup.rate_hz)
        # The gain was chosen for the architecture: gain_marg with a magnetometer, gain_imu without.
        self._f.gain = self._f.gain_marg if self.setup.use_mag else self._f.gain_imu

    def _block(
        self,
        t: NDArray[np.float64],
        gyro: NDArray[np.float64],
        accel: NDArray[np.float64],
        mag: NDArray[np.float64] | None,
        q_out: NDArray[np.float64],
        b_out: NDArray[np.float64] | None,
    ) -> None:
        assert self._q is not None and self._t_last is not None  # process started the filter
        q_out[:], self._t_last = madgwick_block(t, gyro, accel, mag, self._q, self._t_last, self.period, self._f.gain)


class Mahony(_AhrsPeer):
    """Mahony's explicit complementary filter (``ahrs.filters.Mahony``), defaults k_P 1, k_I 0.3."""

    name = "mahony"
    has_bias = True

    def _start(self, q_lib: NDArray[np.float64], accel: NDArray[np.float64], mag: NDArray[np.float64] | None) -> None:
        from ahrs.filters import Mahony as _Mahony

        self._f = _Mahony(frequency=self.setup.rate_hz)

    def _bias(self) -> NDArray[np.float64]:
        return np.array(self._f.b, dtype=float)

    def _block(
        self,
        t: NDArray[np.float64],
        gyro: NDArray[np.float64],
        accel: NDArray[np.float64],
        mag: NDArray[np.float64] | None,
        q_out: NDArray[np.float64],
        b_out: NDArray[np.float64] | None,
    ) -> None:
        assert self._q is not None and self._t_last is not None and b_out is not None  # started, with a bias
        f = self._f
        f.b = np.array(f.b, dtype=float)  # the library's bias integral, carried in place
        q_out[:], b_out[:], self._t_last = mahony_block(
            t, gyro, accel, mag, self._q, f.b, self._t_last, self.period, f.k_P, f.k_I
        )


class AhrsEkf(_AhrsPeer):
    """The quaternion EKF of ``ahrs.filters.EKF`` (state q only), default noises, NED with −accel."""

    name = "ahrs-ekf"
    _to_enu = _Q_NED_TO_ENU

    def _start(self, q_lib: NDArray[np.float64], accel: NDArray[np.float64], mag: NDArray[np.float64] | None) -> None:
        from ahrs.filters import EKF

        kwargs: dict[str, float] = {}
        if mag is not None:
            up, m = accel / np.linalg.norm(accel), mag / np.linalg.norm(mag)
            kwargs["magnetic_ref"] = float(np.degrees(np.arcsin(np.clip(-up @ m, -1.0, 1.0))))  # dip, down +
        self._f = EKF(frequency=self.setup.rate_hz, frame="NED", q0=q_lib, **kwargs)
        self._f.mag = np.zeros((1, 3)) if mag is not None else None  # h() and H() switch on this attribute
        self._mag_mode = self._f.mag

    def _step(
        self,
        q: NDArray[np.float64],
        gyro: NDArray[np.float64],
        accel: NDArray[np.float64] | None,
        mag: NDArray[np.float64] | None,
        dt: float,
    ) -> NDArray[np.float64]:
        f = self._f
        if accel is None:  # the library returns q unchanged for a zero accelerometer: predict only
            q_t = f.f(q, gyro, dt)
            F = f.dfdq(gyro, dt)
            W = 0.5 * dt * np.r_[[-q[1:]], q[0] * np.identity(3) + skew(q[1:])]
            f.P = F @ f.P @ F.T + f.g_noise * W @ W.T
            q_next: NDArray[np.float64] = q_t / np.linalg.norm(q_t)
            return q_next
        if self._mag_mode is None:  # started without a field: 6D throughout
            mag = None
        if mag is None and self._mag_mode is not None:
            f.mag = None
            try:
                q_6d: NDArray[np.float64] = f.update(q, gyro, -accel, None, dt=dt)
                return q_6d
            finally:
                f.mag = self._mag_mode
        q_new: NDArray[np.float64] = f.update(q, gyro, -accel, mag, dt=dt)
        return q_new

    def _block(
        self,
        t: NDArray[np.float64],
        gyro: NDArray[np.float64],
        accel: NDArray[np.float64],
        mag: NDArray[np.float64] | None,
        q_out: NDArray[np.float64],
        b_out: NDArray[np.float64] | None,
    ) -> None:
        assert self._q is not None and self._t_last is not None  # process started the filter
        f = self._f
        f.P = np.array(f.P, dtype=float)  # the library's covariance, carried in place
        q_out[:], self._t_last = ekf_block(
            t,
            gyro,
            -accel,  # the library's convention: the gravity vector (down), see the module notes
            None if self._mag_mode is None else mag,  # started without a field: 6D throughout
            self._q,
            f.P,
            self._t_last,
            self.period,
            f.a_ref,
            f.m_ref,
            (f.g_noise, f.a_noise, f.m_noise),
        )


def import_vqf() -> type:
    """The :class:`vqf.VQF` class, or :class:`VqfUnavailable` naming how to install the optional package."""
    try:
        from vqf import VQF
    except ImportError as exc:
        raise VqfUnavailable(
            f"the optional 'vqf' package is not installed (pip install 'gyroemu[vqf]' or pip install vqf): {exc}"
        ) from exc
    vqf_class: type = VQF  # vqf ships no types
    return vqf_class


class Vqf:
    """VQF (Laidig & Seel 2023), the online :class:`vqf.VQF` with its default parameters."""

    name = "vqf"

    def __init__(self, setup: FilterSetup):
        VQF = import_vqf()
        self.setup = setup
        self._f = VQF(1.0 / float(setup.rate_hz))
        self._out_rot = quat_from_rotvec([0.0, 0.0, -setup.declination_rad]) if setup.use_mag else _Q_IDENTITY
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # (q, bias) of the last sample, for held ones

    def _batch(
        self, gyro: NDArray[np.float64], accel: NDArray[np.float64], mag: NDArray[np.float64] | None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        out = self._f.updateBatch(
            np.ascontiguousarray(gyro), np.ascontiguousarray(accel), None if mag is None else np.ascontiguousarray(mag)
        )
        return (out["quat9D"] if mag is not None else out["quat6D"]), out["bias"]

    def process(self, t: ArrayLike, gyro: ArrayLike, accel: ArrayLike, mag: ArrayLike | None = None) -> Estimate:
        t, gyro, accel, mag = _as_inputs(t, gyro, accel, mag, self.setup.use_mag)
        n = len(t)
        # VQF skips an all-zero accelerometer or magnetometer sample: missing values become zeros.
        accel = np.where(np.isfinite(accel).all(axis=1, keepdims=True), accel, 0.0)
        if mag is not None:
            mag = np.where(np.isfinite(mag).all(axis=1, keepdims=True), mag, 0.0)
        finite_g = np.isfinite(gyro).all(axis=1)
        q = np.full((n, 4), np.nan)
        b = np.full((n, 3), np.nan)
        if finite_g.all():
            if n:
                q[:], b[:] = self._batch(gyro, accel, mag)
        else:  # runs of usable samples through the library, missing gyro samples hold the estimate
            edges = np.flatnonzero(np.diff(np.r_[0, finite_g.astype(np.int8), 0]))
            for start, stop in zip(edges[::2], edges[1::2]):
                q[start:stop], b[start:stop] = self._batch(
                    gyro[start:stop], accel[start:stop], None if mag is None else mag[start:stop]
                )
            for k in np.flatnonzero(~finite_g):
                if k > 0 and np.isfinite(q[k - 1, 0]):
                    q[k], b[k] = q[k - 1], b[k - 1]
                elif k == 0 and self._last is not None:
                    q[k], b[k] = self._last
        if n and np.isfinite(q[-1, 0]):
            self._last = (q[-1].copy(), b[-1].copy())
        return Estimate(q_wb=quat_multiply(self._out_rot, q), gyro_bias=b)


class OfflineVqf:
    """offlineVQF (Laidig & Seel 2023), :func:`vqf.offlineVQF` with its default parameters: acausal, it
    filters the whole log forward and backward, so it takes the log in one ``process`` call (an
    offline estimator, to be compared with offline ones such as ``mekf-smooth``).

    offlineVQF has no notion of a missing sample: a non-finite accelerometer or magnetometer sample
    becomes zeros (which VQF skips), a non-finite gyro sample holds the last finite one (zero rate
    before the first). It runs at the fixed ``1/rate_hz``.
    """

    name = "offline-vqf"
    offline = True

    def __init__(self, setup: FilterSetup):
        import_vqf()
        from vqf import offlineVQF

        self.setup = setup
        self._run = offlineVQF
        self._out_rot = quat_from_rotvec([0.0, 0.0, -setup.declination_rad]) if setup.use_mag else _Q_IDENTITY
        self._done = False

    def process(self, t: ArrayLike, gyro: ArrayLike, accel: ArrayLike, mag: ArrayLike | None = None) -> Estimate:
        if self._done:
            raise ValueError("offline-vqf is offline: it takes the whole log in one process() call")
        self._done = True
        t, gyro, accel, mag = _as_inputs(t, gyro, accel, mag, self.setup.use_mag)
        n = len(t)
        if n == 0:
            return Estimate(q_wb=np.empty((0, 4)), gyro_bias=np.empty((0, 3)))
        accel = np.where(np.isfinite(accel).all(axis=1, keepdims=True), accel, 0.0)
        if mag is not None:
            mag = np.ascontiguousarray(np.where(np.isfinite(mag).all(axis=1, keepdims=True), mag, 0.0))
        finite_g = np.isfinite(gyro).all(axis=1)
        if not finite_g.all():  # hold the last finite sample (index of the last finite row up to each k)
            last = np.maximum.accumulate(np.where(finite_g, np.arange(n), -1))
            gyro = np.where((last >= 0)[:, None], gyro[np.maximum(last, 0)], 0.0)
        out = self._run(np.ascontiguousarray(gyro), np.ascontiguousarray(accel), mag, 1.0 / float(self.setup.rate_hz))
        q = out["quat9D"] if mag is not None else out["quat6D"]
        return Estimate(q_wb=quat_multiply(self._out_rot, q), gyro_bias=np.asarray(out["bias"], dtype=float))

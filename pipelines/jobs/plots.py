"""Pictures of logs: ``gyroemu estimate --plot`` and ``gyroemu info --plot``.

Both read the log they draw (:func:`~gyroemu.pipelines.formats.mcap_log.read_mcap`), so a picture shows
what the file holds, and write one PNG beside it (matplotlib, Agg backend, imported when drawing).

- :func:`plot_estimate`: per device with an ``/estimate/imu``, the estimated roll, pitch and yaw against
  the truth's (``/truth/imu``; Tait–Bryan z-y'-x'' angles of ``q_wb``, REP 103), the attitude error over
  time (the angle of ``q_true⁻¹ ⊗ q_est``, the same for every Euler convention), and the gyro bias the
  filter estimated where it gives one (``/imu`` rate less ``/estimate/imu``'s bias-corrected rate).
- :func:`plot_info`: per device, each IMU topic's series: ``/imu`` rate and specific force, and
  ``/mag`` where there is one.

Time axes are seconds from the device's first stamp.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

__all__ = ["plot_estimate", "plot_info", "euler_zyx_deg", "attitude_error_deg"]


def euler_zyx_deg(q_wb: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (N, 3), degrees, of unit quaternions ``q_wb`` (N, 4) (w, x, y, z): the intrinsic
    z-y'-x'' angles, ``R = R_z(yaw) R_y(pitch) R_x(roll)``."""
    from scipy.spatial.transform import Rotation

    q = np.asarray(q_wb, dtype=float)
    out = np.full((len(q), 3), np.nan)
    ok = np.all(np.isfinite(q), axis=1)
    if ok.any():
        yaw_pitch_roll = Rotation.from_quat(q[ok][:, [1, 2, 3, 0]]).as_euler("ZYX", degrees=True)
        out[ok] = yaw_pitch_roll[:, ::-1]
    return out


def attitude_error_deg(q_true: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    """Angle (N,) of the rotation between two attitudes, degrees: ``2 atan2(|v|, |w|)`` of
    ``q_true⁻¹ ⊗ q_est`` (sign-free; exact at small angles)."""
    a = np.asarray(q_true, dtype=float) * np.array([1.0, -1.0, -1.0, -1.0])
    b = np.asarray(q_est, dtype=float)
    w = a[:, 0] * b[:, 0] - np.sum(a[:, 1:] * b[:, 1:], axis=1)
    v = a[:, :1] * b[:, 1:] + b[:, :1] * a[:, 1:] + np.cross(a[:, 1:], b[:, 1:])
    return np.degrees(2 * np.arctan2(np.linalg.norm(v, axis=1), np.abs(w)))


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _quietly_read(path: Path):
    import warnings

    from gyroemu.pipelines.formats.mcap_log import LogWarning, read_mcap

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LogWarning)
        return read_mcap(path)


def plot_estimate(path: str | os.PathLike[str], out: str | os.PathLike[str] | None = None) -> Path:
    """Draw the estimate of the log ``path`` against its truth into ``out`` (default: ``path`` with
    ``.estimate.png``); returns the file written. ``ValueError`` when no device of the log has an
    ``/estimate/imu``."""
    path = Path(path)
    out = Path(out) if out is not None else path.with_suffix(".estimate.png")
    log = _quietly_read(path)
    devices = [d for d in log.devices.values() if d.estimate is not None and d.estimate.q_wb is not None]
    if not devices:
        raise ValueError(f"{path}: no /estimate/imu to draw")
    plt = _pyplot()
    rows = 5
    fig, axes = plt.subplots(rows, len(devices), figsize=(7 * len(devices), 12), sharex="col", squeeze=False)
    for column, dev in enumerate(devices):
        est = dev.estimate
        t0 = float(dev.samples.t[0])
        t = est.t - t0
        angles = euler_zyx_deg(est.q_wb)
        truth = dev.truth if dev.truth is not None and dev.truth.q_wb is not None else None
        true_angles = euler_zyx_deg(truth.q_wb) if truth is not None else None
        for k, name in enumerate(("roll", "pitch", "yaw")):
            ax = axes[k, column]
            if truth is not None and true_angles is not None:
                ax.plot(truth.t - t0, true_angles[:, k], color="0.3", lw=1.2, label="truth")
            ax.plot(t, angles[:, k], color="C0", lw=0.9, label="estimate")
            ax.set_ylabel(f"{name}, °")
            ax.grid(alpha=0.3)
        axes[0, column].set_title(f"{dev.name}: estimate against the truth")
        axes[0, column].legend(loc="upper right", fontsize=8)
        ax = axes[3, column]
        if truth is not None and len(truth) == len(est) and np.allclose(truth.t, est.t, rtol=0, atol=1e-6):
            error = attitude_error_deg(truth.q_wb, est.q_wb)
            ax.plot(t, error, color="C3", lw=0.9)
            rms = float(np.sqrt(np.nanmean(error**2)))
            ax.set_title(f"attitude error: RMS {rms:.3g}°, final {error[-1]:.3g}°", fontsize=9)
        else:
            ax.text(0.5, 0.5, "no truth at the estimate's stamps", ha="center", va="center", transform=ax.transAxes)
        ax.set_ylabel("error, °")
        ax.grid(alpha=0.3)
        ax = axes[4, column]
        if est.omega_b is not None and len(est) == len(dev.samples):
            bias = np.degrees(dev.samples.gyro - est.omega_b) * 3600.0
            for k, axis in enumerate("xyz"):
                ax.plot(t, bias[:, k], lw=0.9, label=f"b{axis}")
            ax.legend(loc="upper right", fontsize=8)
        else:
            ax.text(0.5, 0.5, "the filter gives no bias", ha="center", va="center", transform=ax.transAxes)
        ax.set_ylabel("gyro bias, °/h")
        ax.set_xlabel("time, s")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def plot_info(path: str | os.PathLike[str], out: str | os.PathLike[str] | None = None) -> Path:
    """Draw each IMU topic's series of the log ``path`` (per device: rate, specific force, field) into
    ``out`` (default: ``path`` with ``.info.png``); returns the file written."""
    path = Path(path)
    out = Path(out) if out is not None else path.with_suffix(".info.png")
    log = _quietly_read(path)
    devices = list(log.devices.values())
    plt = _pyplot()
    fig, axes = plt.subplots(3, len(devices), figsize=(7 * len(devices), 9), sharex="col", squeeze=False)
    for column, dev in enumerate(devices):
        s = dev.samples
        t = s.t - s.t[0]
        panels = (
            (np.degrees(s.gyro), "rate, °/s", dev.topics.get("imu", "/imu")),
            (s.accel, "specific force, m/s²", dev.topics.get("imu", "/imu")),
            (s.mag * 1e6 if s.has_mag else None, "field, µT", dev.topics.get("mag", "/mag")),
        )
        for row, (values, label, topic) in enumerate(panels):
            ax = axes[row, column]
            if values is None:
                ax.text(0.5, 0.5, "no magnetometer", ha="center", va="center", transform=ax.transAxes)
            else:
                for k, axis in enumerate("xyz"):
                    ax.plot(t, values[:, k], lw=0.7, label=axis)
                ax.legend(loc="upper right", fontsize=8)
            ax.set_ylabel(label)
            ax.set_title(f"{dev.name}: {topic}", fontsize=9)
            ax.grid(alpha=0.3)
        axes[-1, column].set_xlabel("time, s")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out

"""The sensors' residuals at rest, real and twin: measured minus truth over the recording's rest phases,
as Allan deviations per axis at :data:`TAUS_S` and Welch spectra, and their pooling over recordings and
seeds.

Residuals. Measured minus truth, over the rest phases of the real recording
(:func:`gyroemu.pipelines.twin.recording.rest_phases`), pooled: real gyro and accelerometer minus the
log's truth rate and specific force when it has them (an MCAP log), else minus 0 and the still body's
``R_bw (0, 0, g)`` (BROAD); twin gyro and accelerometer minus the trajectory's truth at the instants they
measured (the sample's instant minus the sensor's latency). Their Allan deviations per axis at τ from
0.01 to 10 s (those a phase holds twice; the phases' Allan variances weighted by their clusters), the
twin's (RMS over seeds) over the real's per τ, and Welch spectra (averaged over the phases). (At rest
the real body is still: its truth is taken as ω = 0 and the phase's mean of ``R_bw (0, 0, g)``; the
optical attitude sample by sample is dominated by its noise there: several °/s differentiated, and
an Allan bump near τ = 1 s seen through gravity.)
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = [
    "TAUS_S",
    "residual_allan",
    "welch_spectrum",
    "rest_residuals",
    "pool_adev",
    "rms_over_seeds",
    "pooled_residuals",
]

TAUS_S = np.logspace(-2, 1, 16)
"""The averaging times of the residuals' Allan deviations, s."""


def residual_allan(segments: list[np.ndarray], dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(len(TAUS_S), 3) Allan deviation per axis at TAUS_S, pooled over the segments (each (n_i, 3)): the
    Allan variances weighted by their clusters, as :func:`gyroemu.pipelines.identification.pooled_allan`
    does (NaN where every segment is shorter than 2 τ); and the clusters behind each value."""
    from gyroemu.sensors.allan import allan_deviation

    avar = np.zeros((len(TAUS_S), 3))
    clusters = np.zeros((len(TAUS_S), 3))
    for x in segments:
        taus = TAUS_S[(TAUS_S >= dt) & (TAUS_S <= 0.5 * len(x) * dt)]
        if len(x) < 8 or not len(taus):
            continue
        for axis in range(3):
            a = allan_deviation(x[:, axis] - np.mean(x[:, axis]), dt, taus=taus)
            for tau, adev, n in zip(a.tau, a.adev, a.clusters):
                i = int(np.argmin(np.abs(np.log(TAUS_S / tau))))
                if abs(math.log(TAUS_S[i] / tau)) < 0.1:
                    avar[i, axis] += n * adev**2
                    clusters[i, axis] += n
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(clusters > 0, np.sqrt(avar / np.maximum(clusters, 1)), np.nan), clusters


def welch_spectrum(segments: list[np.ndarray], fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Welch spectrum per axis averaged over the segments, weighted by their lengths."""
    from scipy.signal import welch

    shortest = min(len(x) for x in segments)
    nper = int(min(shortest, 2 ** int(math.log2(max(8.0, 2.0 * fs)))))
    total, weight, f = None, 0, np.zeros(0)
    for x in segments:
        f, p = welch(x - x.mean(axis=0), fs=fs, nperseg=nper, axis=0)
        total = p * len(x) if total is None else total + p * len(x)
        weight += len(x)
    return f, (total / weight if total is not None else np.zeros((0, 3)))


def rest_residuals(gyro_res: list[np.ndarray], accel_res: list[np.ndarray], fs: float) -> dict[str, Any]:
    """Allan deviations, spectra and standard deviations of the residuals over the rest segments."""
    gs, acs = [], []
    for g, a in zip(gyro_res, accel_res):
        ok = np.isfinite(g).all(axis=1) & np.isfinite(a).all(axis=1)
        if ok.sum() >= 16:
            gs.append(g[ok])
            acs.append(a[ok])
    out: dict[str, Any] = {"samples": int(sum(len(x) for x in gs))}
    for key, xs in (("gyro", gs), ("accel", acs)):
        out[f"{key}_adev"], out[f"{key}_clusters"] = residual_allan(xs, 1.0 / fs)
        if xs:
            out[f"{key}_psd_f"], out[f"{key}_psd"] = welch_spectrum(xs, fs)
            out[f"{key}_std"] = np.std(np.concatenate([x - x.mean(axis=0) for x in xs]), axis=0)
        else:
            out[f"{key}_psd_f"], out[f"{key}_psd"] = np.zeros(0), np.zeros((0, 3))
            out[f"{key}_std"] = np.full(3, np.nan)
    return out


def pool_adev(runs: list[dict[str, Any]], key: str) -> tuple[np.ndarray, np.ndarray]:
    """Allan deviation (len(TAUS_S), 3) pooled over runs (their variances weighted by clusters), clusters."""
    avar = np.zeros((len(TAUS_S), 3))
    clusters = np.zeros((len(TAUS_S), 3))
    for run in runs:
        adev, n = run["residuals"][f"{key}_adev"], run["residuals"][f"{key}_clusters"]
        ok = np.isfinite(adev)
        avar[ok] += n[ok] * adev[ok] ** 2
        clusters += np.where(ok, n, 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(clusters > 0, np.sqrt(avar / np.maximum(clusters, 1)), np.nan), clusters


def rms_over_seeds(values: list[np.ndarray]) -> np.ndarray:
    """The RMS over the seeds (the list) of the finite values, element by element; NaN where no seed has
    one (a recording without rest: no residuals), as ``nanmean`` but without its warning."""
    squares = np.stack(values) ** 2
    finite = np.isfinite(squares)
    count = finite.sum(axis=0)
    mean = np.where(finite, squares, 0.0).sum(axis=0) / np.maximum(count, 1)
    return np.where(count > 0, np.sqrt(mean), np.nan)


def pooled_residuals(real_runs: list[dict[str, Any]], twin_runs_by_seed: list[list[dict[str, Any]]]) -> dict[str, Any]:
    """The residual Allan deviations at rest pooled over every recording's rest phases, real and twin
    (RMS over seeds), their ratio per τ and axis, and the real clusters behind each τ."""
    out: dict[str, Any] = {"tau_s": TAUS_S}
    for key in ("gyro", "accel"):
        real, clusters = pool_adev(real_runs, key)
        twins = [pool_adev(runs, key)[0] for runs in twin_runs_by_seed]
        twin = rms_over_seeds(twins) if twins else np.full_like(real, np.nan)
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = twin / real
        out[key] = {"real_adev": real, "twin_adev": twin, "ratio": ratio, "real_clusters": clusters}
    return out

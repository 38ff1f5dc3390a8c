"""One run of ``gyroemu twin``: the real recording or one of its twins through every filter, and its
residuals at rest.

Filters. Each filter runs 9D (with the magnetometer, when both the recording and the device have one)
and 6D, each side with the :class:`FilterSetup` of what sensed it (the job builds them): the real log
with what ``gyroemu bench`` uses (``setup_from_metadata`` of an MCAP log, its own device and site; the
defaults at the file's rate for a BROAD trial, as ``tests/benchmarks/broad_filters.py``), its twins
with their device in their site when the log's is known, else the same defaults at the device's rate.
Magnetometers go to the filters in tesla (BROAD's µT × 1e-6). Errors are BROAD's
(:mod:`gyroemu.pipelines.estimation.metrics`): RMSE, degrees, over the movement samples with a finite
reference; a twin is scored against the recording's reference at the nearest real sample (real time =
twin time + t0), and over the recording's movement mask carried over the same way. A filter whose
attitude is not finite at a counted sample has diverged: its run fails, as one that raises does.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from .motion import twin_scenario, twin_seed
from .recording import Recording, measured_field
from .residuals import rest_residuals
from .site import Handling

if TYPE_CHECKING:
    from gyroemu.pipelines.estimation.protocol import FilterSetup
    from gyroemu.pipelines.recorded_scenario import RecordedSpec

__all__ = ["METRICS", "GRAVITY_M_S2", "counted_samples", "filter_errors", "run_real", "run_one_twin"]

METRICS = ("total_9d", "heading_9d", "inclination_9d", "inclination_6d")
"""The errors each filter is scored by (BROAD's), degrees."""
GRAVITY_M_S2 = 9.81
"""The still body's specific force at a BROAD trial's rest, m/s² (its log has no truth force)."""


def counted_samples(mask: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    """The samples a filter is scored on (N,) bool: in ``mask`` (N,) with a finite reference ``q_true`` (N, 4)."""
    return np.asarray(mask & np.isfinite(q_true).all(axis=1), dtype=bool)


def filter_errors(
    filters: list[str],
    setup9: FilterSetup | None,
    setup6: FilterSetup | None,
    t: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    mag: np.ndarray | None,
    q_true: np.ndarray,
    mask: np.ndarray,
    timings: dict[str, float],
) -> dict[str, dict[str, Any]]:
    """{filter: {metric: RMSE deg or None, "error": what failed or None}} of each filter run over ``t``
    (N,) s, ``gyro`` rad/s, ``accel`` m/s², ``mag`` T (9D with ``setup9``, 6D with ``setup6``; None: not
    run), scored against ``q_true`` (N, 4) over ``mask`` (N,); wall times added to ``timings``.

    A run fails, its metrics None and "error" saying why (each failed mode's, "9d: …; 6d: …"), when the
    filter raises, returns no (N, 4) attitude, or returns a non-finite one at a counted sample (a
    filter diverged partway would otherwise be scored over the samples before, and look better)."""
    from gyroemu.pipelines.estimation.metrics import attitude_errors, rmse_deg
    from gyroemu.pipelines.estimation.registry import make_filter

    counted = counted_samples(mask, q_true)
    out: dict[str, dict[str, Any]] = {}
    for spec in filters:
        row: dict[str, Any] = dict.fromkeys(METRICS)
        failures = []
        for mode, setup in (("9d", setup9), ("6d", setup6)):
            if setup is None:
                continue
            started = time.perf_counter()
            try:
                est = make_filter(spec, setup).process(t, gyro, accel, mag if mode == "9d" else None)
                q = np.asarray(est.q_wb, float)
                if q.shape != (len(t), 4):
                    raise ValueError(f"returned q_wb of shape {q.shape}")
            except Exception as exc:  # noqa: BLE001 - a failing filter is reported, not fatal
                failures.append(f"{mode}: {type(exc).__name__}: {exc}")
                continue
            finally:
                timings[f"filter {spec} {mode}"] = timings.get(f"filter {spec} {mode}", 0.0) + (
                    time.perf_counter() - started
                )
            lost = counted & ~np.isfinite(q).all(axis=1)
            if lost.any():
                first = int(np.flatnonzero(lost)[0])
                failures.append(
                    f"{mode}: diverged: a non-finite attitude at {int(lost.sum())} of {int(counted.sum())} counted "
                    f"samples, the first at t = {float(t[first]):.6g} s"
                )
                continue
            with np.errstate(invalid="ignore", divide="ignore"):
                err = attitude_errors(q, q_true)
            if mode == "9d":
                row["total_9d"] = rmse_deg(err.total, counted)
                row["heading_9d"] = rmse_deg(err.heading, counted)
                row["inclination_9d"] = rmse_deg(err.inclination, counted)
            else:
                row["inclination_6d"] = rmse_deg(err.inclination, counted)
        row["error"] = "; ".join(failures) or None
        out[spec] = row
    return out


def run_real(
    real: Recording, filters: list[str], setup9: FilterSetup | None, setup6: FilterSetup, rests: list[slice]
) -> dict[str, Any]:
    """The real recording ``real``: every filter's errors (9D with ``setup9`` unless None, 6D with ``setup6``)
    and the residuals at rest over the samples ``rests``, with wall times."""
    from gyroemu.pipelines.identification.truth import rotation_bw

    timings: dict[str, float] = {}
    errors = filter_errors(
        filters, setup9, setup6, real.t, real.gyro, real.accel, real.mag, real.q_true, real.mask, timings
    )
    started = time.perf_counter()
    # At rest the body is still: the truth is ω = 0 (Earth's rate, ≤ 0.0042 °/s, is constant: no Allan
    # or spectral content) and a constant f, R_bw (0, 0, g) averaged over the phase. The optical
    # attitude sample by sample would be its noise: differentiated, several °/s; seen through gravity,
    # 2.9·10⁻³ m/s² at τ ≈ 1 s on y, an Allan bump the raw accelerometer does not have (README, "The
    # twin"). A log's own truth rate and specific force are used when it has them.
    gyro_res, accel_res = [], []
    for rest in rests:
        q = real.q_true[rest]
        omega = np.zeros((len(q), 3)) if real.omega_true is None else real.omega_true[rest]
        if real.force_true is None:
            gravity_b = np.einsum("nij,j->ni", rotation_bw(q), np.array([0.0, 0.0, GRAVITY_M_S2]))
            force = np.broadcast_to(np.nanmean(gravity_b, axis=0), gravity_b.shape)
        else:
            force = real.force_true[rest]
        gyro_res.append(real.gyro[rest] - omega)
        accel_res.append(real.accel[rest] - force)
    res = rest_residuals(gyro_res, accel_res, real.rate_hz)
    timings["residuals"] = time.perf_counter() - started
    return {"errors": errors, "residuals": res, "timings": timings}


def run_one_twin(
    real: Recording,
    site: dict[str, Any],
    smoothing: dict[str, Any] | None,
    device_name: str,
    seed: int,
    filters: list[str],
    setup9: FilterSetup | None,
    setup6: FilterSetup,
    rest_t: list[tuple[float, float]],
    attitude: np.ndarray | None = None,
    handling: Handling | None = None,
) -> dict[str, Any]:
    """Twin ``seed`` of ``real`` (its device ``device_name`` and site drawn from :func:`twin_seed`): the
    recorded motion (with the refined ``attitude`` when given) sensed by the device, every filter's
    errors against the recording's reference, and the residuals over the rest stretches ``rest_t``
    ((start, stop), s of the recording), with the ``handling`` offset over the movement when given."""
    from gyroemu.sensors import load_device
    from gyroemu.sensors.sampling import SensorTruth

    timings: dict[str, float] = {}
    started = time.perf_counter()
    seed = twin_seed(seed, real.name, real.same_name_index)
    scenario = twin_scenario(real, site, seed, smoothing)
    device = load_device(device_name, seed=seed)
    spec = cast("RecordedSpec", scenario.spec)  # twin_scenario's kind is "recorded"
    if attitude is not None:  # the recording's twin attitude (:func:`twin_attitude`), the same for every seed
        spec.replace_attitude(real.t, attitude)
    t0 = float(spec.motion().t0)
    timings["scenario (load, fit)"] = time.perf_counter() - started
    started = time.perf_counter()
    traj = scenario.simulate(rate_hz=device.spec.rate_hz)
    timings["simulate"] = time.perf_counter() - started
    started = time.perf_counter()
    samples = device.measure(traj)
    timings["measure"] = time.perf_counter() - started
    started = time.perf_counter()
    body = SensorTruth(traj)  # the trajectory's interpolants, for the truth at τ and at τ − latency
    instants = np.asarray(samples.t_true if samples.t_true is not None else samples.t, float)
    timings["truth"] = time.perf_counter() - started
    # The real trial's mask, by the nearest real sample to each twin instant (real time = t + t0).
    real_time = instants + t0
    k = np.clip(np.searchsorted(real.t, real_time), 1, len(real.t) - 1)
    k = np.where(np.abs(real.t[k - 1] - real_time) <= np.abs(real.t[k] - real_time), k - 1, k)
    inside = (real_time >= real.t[0] - 0.5 / real.rate_hz) & (real_time <= real.t[-1] + 0.5 / real.rate_hz)
    mask = real.mask[k] & inside
    t = np.asarray(samples.t, float)
    # Carried, the accelerometer reads against the truth otherwise than at rest ([handling] of the site
    # file, identified between the rest phases and the movement): the offset applies over the recording's
    # movement mask (a recording without one does not say when the device was carried: none).
    accel = np.asarray(samples.accel, float)
    offset = None
    if handling is not None and real.counted == "movement mask":
        offset = handling.draw(seed)
        accel = accel + np.where(mask[:, None], offset, 0.0)
    mag = None if samples.mag is None else measured_field(np.asarray(samples.mag, float))
    # Scored as the real log is, against the recording's reference (the nearest sample): its noise is in
    # the real errors, so it is in the twins' (their motion is the reference refined by the gyro).
    reference = np.where(inside[:, None], real.q_true[k], np.nan)
    errors = filter_errors(
        filters,
        setup9 if mag is not None else None,
        setup6,
        t,
        samples.gyro,
        accel,
        mag,
        reference,
        mask,
        timings,
    )
    started = time.perf_counter()
    # The sensor's error: measured minus the truth at the instant each sensor measured, τ − latency (at
    # rest the real truth is still, and so is the twins' motion, held at its mean there).
    lat_gyro, lat_accel, _ = device.latencies
    span = (float(traj.t[0]), float(traj.t[-1]))
    omega_at = body.body_truth(np.clip(instants - lat_gyro, *span))[1]
    force_at = body.body_truth(np.clip(instants - lat_accel, *span))[2]
    gyro_res, accel_res = [], []
    for start, stop in rest_t:
        at_rest = (real_time >= start) & (real_time <= stop)
        gyro_res.append(samples.gyro[at_rest] - omega_at[at_rest])
        accel_res.append(samples.accel[at_rest] - force_at[at_rest])
    res = rest_residuals(gyro_res, accel_res, float(device.spec.rate_hz))
    timings["residuals"] = time.perf_counter() - started
    return {
        "errors": errors,
        "residuals": res,
        "timings": timings,
        "t0": t0,
        "samples": len(t),
        "counted": int(counted_samples(mask, reference).sum()),
        "handling_offset": None if offset is None else [float(x) for x in offset],
    }

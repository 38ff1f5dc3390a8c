"""Several recordings of one device pooled into a device config and a site snippet (TOML).

Per-trial estimates x_i ± σ_i (of the trials where the term was observable) are pooled by the
inverse-variance weighted mean, its uncertainty inflated by the Birge ratio when the trials scatter
more than their own uncertainties say (a formal σ from correlated residuals is optimistic):

    x̄ = Σ x_i/σ_i² / Σ 1/σ_i²,    σ̄ = max(1, √(χ²/(n−1))) / √(Σ 1/σ_i²),    χ² = Σ (x_i − x̄)²/σ_i²

The gyro bias of each trial is one power-up: the device's ``bias_deg_per_h`` is their mean and, with
two trials or more, ``turn_on_bias_deg_per_h`` their standard deviation. So is its scale factor: on
BROAD's aktos-t the four undisturbed trials give z scale factors of −2047 ± 590, +2265 ± 114,
+761 ± 596 and +2837 ± 186 ppm (χ² = 69 on 3 degrees of freedom), all three axes of a trial moving
together, so the scale factor is not one number but one draw per power-up (a repeatability, IEEE 1431's
turn-on to turn-on scale-factor term). The scale factors are therefore pooled as a random-effects
mean (DerSimonian and Laird, 1986): with w_i = 1/σ_i², Q the χ² above about the weighted mean and k
the trials, the spread between power-ups

    τ² = max(0, (Q − (k − 1)) / (Σ w_i − Σ w_i² / Σ w_i)),    x̄ = Σ x_i/(σ_i² + τ²) / Σ 1/(σ_i² + τ²),
    σ̄ = 1/√(Σ 1/(σ_i² + τ²))

(:func:`pool_random_effects`); ``scale_factor_ppm`` is x̄ and ``turn_on_scale_factor_ppm`` τ, drawn
once per power-up by the device. The fixed-effects mean would be the best-determined trial's (the
fast rotation's +2265 ppm on z, then given to every twin); its twin of the stationary-magnet trial put
VQF's 9D error at 2.9 times the real one, 1.9 times with the scale drawn per twin. Noise terms come from the
rest phases of every trial pooled (:func:`gyroemu.pipelines.identification.noise.sensor_noise`), the
gyro's and accelerometer's with a Gauss–Markov term where it is significant (written as
``markov_sigma_*`` and ``markov_tau_s``, 0 on axes without it).

The device TOML uses the device keys of :class:`gyroemu.sensors.imu.DeviceSpec` plus the per-sensor
``latency_s``; the uncertainties, what was not observable and the provenance are written as comments.
The site snippet holds ``[site] magnetic_field_enu_uT`` (the rest field, in the truth's world frame,
as strong as the calibrated magnetometer measures it) and ``[site.magnetic_environment]``, and
``[handling]``: the accelerometer's offset in the movement against at rest (:mod:`.handling`), as the
mean and the standard deviation across the recordings (each handling of the device is one draw).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyroemu.dynamics.rotation import quat_from_matrix

from .calibration import polar_decomposition
from .handling import pool_handling_offsets
from .magnetic_environment import (
    FIELD_AGREEMENT,
    MagneticEnvironment,
    discordant_fields,
    magnetic_environment,
    pool_heading_offsets,
    world_field,
)
from .noise import SensorNoise, sensor_noise
from .timing import LatencyEstimate
from .trial import TrialData, TrialIdentification, TrialSettings, identify_trial
from .truth import interpolate_attitude, rotation_bw

__all__ = ["Pooled", "Identification", "pool_estimates", "pool_random_effects", "identify"]

_DEG = 180.0 / np.pi
_G0 = 9.80665
_UG = 1e-6 * _G0


@dataclass(frozen=True)
class Pooled:
    """A pooled estimate: value and standard uncertainty (arrays of any shape), the trials used."""

    value: NDArray[np.float64]
    sigma: NDArray[np.float64]
    trials: int


def _inverse_variance(
    values: Sequence[NDArray[np.float64]], sigmas: Sequence[NDArray[np.float64]]
) -> tuple[
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.bool_],
    NDArray[np.float64],
    NDArray[np.bool_],
    NDArray[np.float64],
]:
    """The inputs as arrays (k, ...), which σ are known (finite, > 0), their weights 1/σ² (0 where
    unknown), which elements have any weight, and the weights' sum (1 where none: safe to divide)."""
    x = np.asarray(values, dtype=float)
    s = np.asarray(sigmas, dtype=float)
    if not len(x):
        raise ValueError("nothing to pool")
    known = np.isfinite(s) & (s > 0)
    w = np.where(known, 1.0 / np.where(known, s, 1.0) ** 2, 0.0)
    total = np.sum(w, axis=0)
    weighted = total > 0  # elements without any uncertainty (fixed zeros): plain mean, σ 0
    return x, s, known, w, weighted, np.where(weighted, total, 1.0)


def pool_estimates(values: Sequence[NDArray[np.float64]], sigmas: Sequence[NDArray[np.float64]]) -> Pooled:
    """Inverse-variance mean with Birge inflation (module notes), element by element."""
    x, _, _, w, weighted, safe = _inverse_variance(values, sigmas)
    mean = np.where(weighted, np.sum(w * x, axis=0) / safe, x.mean(axis=0))
    sigma = np.where(weighted, 1.0 / np.sqrt(safe), 0.0)
    if len(x) > 1:
        birge = np.sqrt(np.sum(w * (x - mean) ** 2, axis=0) / (len(x) - 1))
        sigma = sigma * np.maximum(1.0, birge)
    return Pooled(mean, sigma, len(x))


def pool_random_effects(
    values: Sequence[NDArray[np.float64]], sigmas: Sequence[NDArray[np.float64]]
) -> tuple[Pooled, NDArray[np.float64]]:
    """Random-effects mean of per-trial estimates ``values`` ± ``sigmas`` (each an array of one shape),
    element by element (module notes, DerSimonian and Laird): the pooled estimate and τ, the standard
    deviation of the true values between trials (0 where the trials agree within their σ_i). Elements
    without a finite positive σ in any trial: the plain mean, σ and τ 0."""
    x, s, known, w, weighted, safe = _inverse_variance(values, sigmas)
    s2 = np.where(known, s, 1.0) ** 2
    fixed = np.sum(w * x, axis=0) / safe
    q = np.sum(w * (x - fixed) ** 2, axis=0)
    dof = np.sum(known, axis=0) - 1
    denominator = safe - np.sum(w**2, axis=0) / safe
    tau2 = np.where(
        weighted & (dof > 0) & (denominator > 0),
        np.maximum(0.0, (q - dof) / np.where(denominator > 0, denominator, 1.0)),
        0.0,
    )
    w_re = np.where(known, 1.0 / (s2 + tau2), 0.0)
    total_re = np.where(weighted, np.sum(w_re, axis=0), 1.0)
    mean = np.where(weighted, np.sum(w_re * x, axis=0) / total_re, x.mean(axis=0))
    sigma = np.where(weighted, 1.0 / np.sqrt(total_re), 0.0)
    return Pooled(mean, sigma, len(x)), np.sqrt(tau2)


@dataclass(frozen=True, eq=False)
class Identification:
    """Everything identified from a set of recordings of one device."""

    trials: list[TrialIdentification]
    rate_hz: float
    latency: dict[str, Pooled]  # sensor -> Pooled (s)
    gyro_bias: Pooled  # rad/s
    gyro_bias_spread: NDArray[np.float64]  # (3,) rad/s, std across trials (0 for one trial)
    gyro_scale: Pooled | None  # random-effects mean (module notes)
    gyro_misalignment: Pooled | None
    c_sb: NDArray[np.float64]
    accel_bias: Pooled
    accel_scale: Pooled | None
    accel_cross_axis: Pooled | None
    hard_iron: Pooled | None
    soft_iron: Pooled | None
    k_matrix: NDArray[np.float64] | None
    gyro_noise: SensorNoise | None
    accel_noise: SensorNoise | None
    mag_noise: SensorNoise | None
    environments: list[MagneticEnvironment | None]
    notes: list[str]
    handling: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None  # (3,) mean, (3,) std across trials, m/s²
    lever_arm: Pooled | None = None  # (3,) m, body axes: the accelerometer's lever arm from the truth's origin
    gyro_scale_spread: NDArray[np.float64] | None = None  # (3,) τ, the scale factor's spread between power-ups
    latency_bounds: frozenset[str] = frozenset()  # sensors whose latency no trial resolved: not written

    # ----------------------------------------------------------------------------------------------
    def device_dict(self) -> dict[str, Any]:
        """The device config (keys of :class:`gyroemu.sensors.imu.DeviceSpec`, plus ``latency_s``)."""
        names = ", ".join(t.name for t in self.trials)
        gyro_errors: dict[str, Any] = {"bias_deg_per_h": _list(self.gyro_bias.value * _DEG * 3600)}
        if len(self.trials) > 1:
            gyro_errors["turn_on_bias_deg_per_h"] = _list(self.gyro_bias_spread * _DEG * 3600)
        if self.gyro_scale is not None and self.gyro_misalignment is not None:
            gyro_errors["scale_factor_ppm"] = _list(self.gyro_scale.value * 1e6)
            if len(self.trials) > 1 and self.gyro_scale_spread is not None:
                gyro_errors["turn_on_scale_factor_ppm"] = _list(self.gyro_scale_spread * 1e6)
            gyro_errors["cross_axis_matrix"] = [_list(r) for r in self.gyro_misalignment.value]
        if self.gyro_noise is not None:
            n = self.gyro_noise
            gyro_errors["noise_density_deg_per_s_per_sqrt_hz"] = _list(n.values("noise_density") * _DEG, 4)
            gyro_errors["bias_instability_deg_per_h"] = _list(n.values("bias_instability") * _DEG * 3600, 4)
            gyro_errors["rrw_deg_per_h_per_sqrt_h"] = _list(n.values("random_walk") * _DEG * 3600 * 60, 4)
            markov = n.markov()
            if markov is not None:
                gyro_errors["markov_sigma_deg_per_h"] = _list(markov[0] * _DEG * 3600, 4)
                gyro_errors["markov_tau_s"] = _list(markov[1], 4)
        accel_errors: dict[str, Any] = {"bias_ug": _list(self.accel_bias.value / _UG)}
        if self.accel_scale is not None and self.accel_cross_axis is not None:
            accel_errors["scale_factor_ppm"] = _list(self.accel_scale.value * 1e6)
            accel_errors["cross_axis_matrix"] = [_list(r) for r in self.accel_cross_axis.value]
        if self.accel_noise is not None:
            n = self.accel_noise
            accel_errors["noise_density_ug_per_sqrt_hz"] = _list(n.values("noise_density") / _UG, 4)
            accel_errors["bias_instability_ug"] = _list(n.values("bias_instability") / _UG, 4)
            accel_errors["random_walk_ug_per_sqrt_h"] = _list(n.values("random_walk") / _UG * 60, 4)
            markov = n.markov()
            if markov is not None:
                accel_errors["markov_sigma_ug"] = _list(markov[0] / _UG, 4)
                accel_errors["markov_tau_s"] = _list(markov[1], 4)
        q_bs = quat_from_matrix(self.c_sb.T)
        # A measured latency d is the delay of the instant a sample matches (the truth at t − d). gyroemu's
        # gyro and accelerometer samples are means over their interval [τ − T, τ] shifted by latency_s,
        # which matches the motion at its middle, τ − T/2 − latency_s (to second order in T): the
        # device's latency_s = d − T/2. Its magnetometer samples at τ − latency_s: latency_s = d.
        half = 0.5 / float(self.rate_hz)
        out: dict[str, Any] = {
            "description": f"Identified by gyroemu identify from {names}",
            "rate_hz": round(float(self.rate_hz), 6),
            "mounting": {"q_bs": _list(q_bs, 9)}
            | ({} if self.lever_arm is None else {"lever_arm_m": _list(self.lever_arm.value, 4)}),
            "gyro": self._latency_key("gyro", half) | {"errors": gyro_errors},
            "accelerometer": self._latency_key("accelerometer", half) | {"errors": accel_errors},
        }
        if "magnetometer" in self.latency:
            mag: dict[str, Any] = self._latency_key("magnetometer", 0.0)
            if self.mag_noise is not None:
                mag["noise_density_uT_per_sqrt_hz"] = round(
                    float(np.mean(self.mag_noise.values("noise_density"))) * 1e6, 5
                )
            if self.hard_iron is not None and self.soft_iron is not None:
                mag["hard_iron_uT"] = _list(self.hard_iron.value * 1e6)
                mag["soft_iron"] = [_list(r, 5) for r in self.soft_iron.value]
            out["magnetometer"] = mag
        return out

    def device_comments(self) -> list[str]:
        """Comment lines (without '#'): provenance, uncertainties (1σ), what was not observable."""
        lines = [
            "Fitted by 'gyroemu identify'. Uncertainties are standard (1 sigma); noise intervals 68 %.",
            "Noise densities are Allan readings (N = Allan deviation at 1 s, fitted from the rest phases'",
            "Allan deviations): N as gyroemu draws it, not a one-sided spectral density (sensors/noise.py).",
        ]
        for t in self.trials:
            rest = ", ".join(f"{p.t_start:.1f}-{p.t_stop:.1f} s" for p in t.rest) or "none"
            lines.append(f"trial {t.name}: {t.samples} samples at {t.rate_hz:.3f} Hz; rest phases {rest}")
            lines.append(
                f"  latency ms: gyro {_pm(t.gyro_latency.latency_s * 1e3, t.gyro_latency.sigma_s * 1e3)}, accel "
                f"{_pm(t.accel_latency.latency_s * 1e3, t.accel_latency.sigma_s * 1e3)}"
                + (
                    f", mag {_pm(t.mag_latency.latency_s * 1e3, t.mag_latency.sigma_s * 1e3)}"
                    if t.mag_latency is not None
                    else ""
                )
            )
            for what, note in (
                ("gyro", t.gyro.note),
                ("accelerometer", t.accel.note),
                ("magnetometer", t.mag.note if t.mag else ""),
            ):
                if note:
                    lines.append(f"  {what}: {note}")
            lines.extend(f"  {n}" for n in t.notes)
        for sensor, p in self.latency.items():
            if sensor in self.latency_bounds:
                lines.append(
                    f"{sensor}: delay not resolved in any trial ({_pm(p.value, p.sigma)} s: at the edge of the "
                    "search, or uncertain beyond it): a bound, not a fit, so no latency_s is written"
                )
                continue
            lines.append(
                f"{sensor}: measured delay {_pm(p.value, p.sigma)} s over {p.trials} trials"
                + (" (latency_s = delay − T/2: the interval mean adds T/2)" if sensor != "magnetometer" else "")
            )
        lines.append(f"gyro.errors.bias_deg_per_h sigma {_list(self.gyro_bias.sigma * _DEG * 3600)}")
        arms = [(t.name, t.lever_arm) for t in self.trials if t.lever_arm is not None]
        if self.lever_arm is not None:
            lines.append(
                f"mounting.lever_arm_m sigma {_list(self.lever_arm.sigma, 3)} ({self.lever_arm.trials} trials; the "
                "accelerometer from the truth's origin, f = ... + alpha x r + w x (w x r)); per trial, mm:"
            )
            for name, arm in arms:
                lines.append(
                    f"  {name}: {_list(arm.lever_arm_b * 1e3, 3)} +- {_list(arm.lever_arm_sigma * 1e3, 2)}; "
                    f"residual rms {_list(arm.rms_before, 3)} -> {_list(arm.residual_rms, 3)} m/s^2 over "
                    f"{arm.windows} windows"
                )
        if self.gyro_scale is not None and self.gyro_misalignment is not None:
            lines.append(
                f"gyro.errors.scale_factor_ppm sigma {_list(self.gyro_scale.sigma * 1e6)} "
                f"({self.gyro_scale.trials} trials; random-effects mean, its spread between power-ups "
                f"{_list((self.gyro_scale_spread if self.gyro_scale_spread is not None else np.zeros(3)) * 1e6)})"
            )
            for t in self.trials:
                if t.gyro.observable:
                    lines.append(f"  {t.name}: {_list(t.gyro.scale * 1e6)} +- {_list(t.gyro.scale_sigma * 1e6)} ppm")
            lines.append(f"gyro.errors.cross_axis_matrix sigma {[_list(r) for r in self.gyro_misalignment.sigma]}")
        else:
            lines.append("gyro scale factor and misalignment: not observable in any trial (not written)")
        lines.append(f"accelerometer.errors.bias_ug sigma {_list(self.accel_bias.sigma / _UG)}")
        if self.accel_scale is not None:
            lines.append(f"accelerometer.errors.scale_factor_ppm sigma {_list(self.accel_scale.sigma * 1e6)}")
        else:
            lines.append(
                "accelerometer scale factor and cross-axis: not observable (too few slow attitudes): not written"
            )
        if self.hard_iron is not None and self.soft_iron is not None:
            lines.append(
                f"magnetometer.hard_iron_uT sigma {_list(self.hard_iron.sigma * 1e6)} ({self.hard_iron.trials} trials)"
            )
            lines.append(
                f"magnetometer.soft_iron sigma {[_list(r, 5) for r in self.soft_iron.sigma]} (normalised: det = 1)"
            )
        elif "magnetometer" in self.latency:
            lines.append("magnetometer hard and soft iron: not observable in any trial (not written)")
        for sensor, noise, scale, unit in (
            (
                "gyro",
                self.gyro_noise,
                (_DEG, _DEG * 3600, _DEG * 3600 * 60),
                ("deg/s/sqrt(Hz)", "deg/h", "deg/h/sqrt(h)"),
            ),
            ("accelerometer", self.accel_noise, (1 / _UG, 1 / _UG, 60 / _UG), ("ug/sqrt(Hz)", "ug", "ug/sqrt(h)")),
            ("magnetometer", self.mag_noise, (1e6, 1e6, 1e6), ("uT/sqrt(Hz)", "uT", "uT/sqrt(s)")),
        ):
            if noise is None:
                continue
            lines.append(
                f"{sensor} noise from {noise.phases} rest phases, {noise.rest_s:.1f} s; "
                f"Allan tau up to {noise.tau_max_s:.3g} s:"
            )
            for term, f, u in zip(("noise_density", "bias_instability", "random_walk"), scale, unit):
                parts = []
                for axis, a in zip("xyz", noise.axes):
                    c = getattr(a, term)
                    if a.noiseless:
                        parts.append(f"{axis} 0 (read a constant at rest: no noise measurable)")
                    elif c.status == "fitted":
                        parts.append(f"{axis} {c.value * f:.4g} [{c.low * f:.4g}, {c.high * f:.4g}]")
                    else:
                        parts.append(f"{axis} < {c.high * f:.4g} (not observable: written 0)")
                lines.append(f"  {term} {u}: " + "; ".join(parts))
            if any(a.model_scatter > 0 for a in noise.axes):
                scatter = "; ".join(f"{axis} {100 * a.model_scatter:.2g} %" for axis, a in zip("xyz", noise.axes))
                lines.append(f"  scatter about the model beyond sampling (in the fit's weights): {scatter}")
            if any(a.band_limit > 0 for a in noise.axes):
                sag = "; ".join(
                    f"{axis} {a.smoothing_s * 1e3:.3g} ms" if a.band_limit > 0 else f"{axis} none"
                    for axis, a in zip("xyz", noise.axes)
                )
                lines.append(
                    f"  band limit of the white noise (a low-pass's sag at short tau, as a time constant): {sag}"
                )
            if any(a.markov is not None for a in noise.axes):
                lines.append(f"  gauss_markov sigma {unit[1]}, tau_c s (kept if F > F_0.99(2, M-6)):")
                for axis, a in zip("xyz", noise.axes):
                    m = a.markov
                    if m is None:
                        continue
                    test = f"F {m.f_ratio:.3g} vs {m.f_critical:.3g}, chi2 {m.chi2_without:.3g} -> {m.chi2_with:.3g}"
                    if m.kept:
                        lines.append(
                            f"    {axis} {m.sigma.value * scale[1]:.4g} [{m.sigma.low * scale[1]:.4g}, "
                            f"{m.sigma.high * scale[1]:.4g}] at tau_c {m.tau_c.value:.3g} "
                            f"[{m.tau_c.low:.3g}, {m.tau_c.high:.3g}] ({test})"
                        )
                    else:
                        lines.append(
                            f"    {axis} < {m.sigma.high * scale[1]:.4g} (best tau_c "
                            f"{m.tau_c.low:.3g}-{m.tau_c.high:.3g}; not significant: {test}; not written)"
                        )
        lines.extend(self.notes)
        return lines

    def _latency_key(self, sensor: str, half: float) -> dict[str, float]:
        """``{"latency_s": delay − half}`` for a fitted delay; nothing for a bound (:attr:`latency_bounds`)."""
        if sensor in self.latency_bounds:
            return {}
        return {"latency_s": round(float(self.latency[sensor].value) - half, 6)}

    def device_toml(self) -> str:
        """The device config as TOML text, comments first."""
        import tomli_w

        head = "".join(f"# {line}\n" for line in self.device_comments())
        return head + "\n" + tomli_w.dumps(self.device_dict())

    # ----------------------------------------------------------------------------------------------
    def site_dict(self) -> dict[str, Any] | None:
        """``[site]`` with ``magnetic_field_enu_uT`` and ``[site.magnetic_environment]`` (with a magnetometer
        environment) and ``[handling]`` (with a handling offset); None with neither."""
        out: dict[str, Any] = {}
        if self.handling is not None:
            offset, spread = self.handling
            out["handling"] = {"accel_offset_m_s2": _list(offset, 4), "accel_offset_sigma_m_s2": _list(spread, 4)}
        envs = [e for e in self.environments if e is not None]
        if not envs:
            return out or None
        mean, sigma = pool_heading_offsets(envs)
        field = np.mean([e.rest_field_w for e in envs], axis=0)
        env: dict[str, Any] = {
            "spatial_sigma_uT": round(float(np.mean([e.spatial_sigma for e in envs])) * 1e6, 4),
            "heading_offset_mean_deg": round(float(np.degrees(mean)), 4),
            "heading_offset_sigma_deg": round(float(np.degrees(sigma)), 4),
        }
        lengths = [e.correlation_length_m for e in envs if e.correlation_length_m is not None]
        finite = [x for x in lengths if np.isfinite(x)]
        if finite:
            env["correlation_length_m"] = round(float(np.mean(finite)), 4)
        return {"site": {"magnetic_field_enu_uT": _list(field * 1e6, 4), "magnetic_environment": env}} | out

    def site_toml(self) -> str | None:
        """The site snippet as TOML text with per-trial comments; None without a magnetometer."""
        import tomli_w

        data = self.site_dict()
        if data is None:
            return None
        lines = ["Magnetic environment identified by 'gyroemu identify' (world frame: the truth's ENU)."]
        for t, e in zip(self.trials, self.environments):
            if e is None:
                continue
            corr = (
                f"correlation length {e.correlation_length_m:.3g} m"
                if e.correlation_length_m is not None
                else "no position track: correlation length unavailable"
            )
            lines.append(
                f"{t.name}: |m| {e.norm * 1e6:.2f} uT, dip {np.degrees(e.dip):.2f} deg, "
                f"heading {np.degrees(e.heading):.2f} deg; "
                + (
                    f"spread {_list(e.raw_sigma * 1e6, 3)} uT, of it a function of position "
                    if e.raw_sigma is not None
                    else "spread "
                )
                + f"{_list(e.axis_sigma * 1e6, 3)} uT (E, N, U); heading offset "
                f"{np.degrees(e.heading_offset):.2f} +- {np.degrees(e.heading_offset_sigma):.2f} deg; {corr}; "
                f"correlation time {e.correlation_time_s:.3g} s; {e.samples} movement samples"
            )
        n = sum(e is not None for e in self.environments)
        known = [(t, e) for t, e in zip(self.trials, self.environments) if e is not None]
        for odd in discordant_fields([e for _, e in known]):
            lines.append(
                f"{known[odd.index][0].name}: its field at rest lies {odd.distance * 1e6:.1f} uT from the others' "
                f"median, beyond {FIELD_AGREEMENT:g} times the field's spread along the paths "
                f"({odd.allowed * 1e6:.1f} uT); magnetic_field_enu_uT below is the mean with it"
            )
        if n:
            lines.append(
                "heading_offset_sigma_deg: "
                + (
                    "standard deviation across the trials"
                    if n > 1
                    else "within the one trial (give several logs for a spread across trials)"
                )
            )
        if self.handling is not None:
            lines.append(
                "[handling]: the accelerometer's offset against the truth in the movement minus at rest, sensor axes "
                "(slow windows, |w| < 0.5 rad/s); mean and standard deviation across the trials:"
            )
            for t in self.trials:
                h = t.handling
                if h is None:
                    continue
                lines.append(
                    f"  {t.name}: {_list(h.offset, 3)} +- {_list(h.offset_sigma, 2)} m/s^2 "
                    f"(a tilt of {_list(h.tilt_deg, 3)} deg about x, y); {h.rest_windows} rest and "
                    f"{h.movement_windows} movement windows"
                )
        return "".join(f"# {line}\n" for line in lines) + "\n" + tomli_w.dumps(data)


def _list(x: ArrayLike, digits: int = 6) -> list[float]:
    return [float(f"{v:.{digits}g}") for v in np.ravel(x)]


def _pm(x: float | NDArray[np.float64], s: float | NDArray[np.float64]) -> str:
    # x, s: floats, or a pooled latency's value and sigma (float64s taken from arrays, typed as Pooled's arrays)
    return f"{x:.4g} +- {s:.2g}"


def _pool_latency(estimates: Sequence[LatencyEstimate]) -> Pooled:
    p = pool_estimates([np.array([e.latency_s]) for e in estimates], [np.array([e.sigma_s]) for e in estimates])
    return Pooled(p.value[0], p.sigma[0], p.trials)


def _pool_field(results: Sequence[object], attr: str, sigma_attr: str) -> Pooled | None:
    vals = [getattr(r, attr) for r in results]
    sigs = [getattr(r, sigma_attr) for r in results]
    return pool_estimates(vals, sigs) if vals else None


def identify(trials: Sequence[TrialData], settings: TrialSettings | None = None) -> Identification:
    """Identify each recording (:func:`identify_trial`), pool them (module notes), and map each one's
    magnetic environment with its own magnetometer calibration (or the pooled one where its own is not
    observable)."""
    if not trials:
        raise ValueError("no recordings")
    settings = settings if settings is not None else TrialSettings()
    results = [identify_trial(d, settings) for d in trials]
    notes: list[str] = []
    # A latency at the edge of its search is a bound, not a fit, and one uncertain beyond the search
    # is not resolved: pooled only where no trial resolved one, and then not written into the device
    # (:meth:`Identification.device_toml`).
    latency, latency_bounds = {}, set()
    for sensor, estimates in (
        ("gyro", [r.gyro_latency for r in results]),
        ("accelerometer", [r.accel_latency for r in results]),
        ("magnetometer", [r.mag_latency for r in results if r.mag_latency is not None]),
    ):
        fitted = [e for e in estimates if not e.at_edge and e.sigma_s < settings.search_s]
        if fitted or estimates:
            latency[sensor] = _pool_latency(fitted or estimates)
        if estimates and not fitted:
            latency_bounds.add(sensor)

    gyros = [r.gyro for r in results if r.gyro.observable]
    biases = np.array([r.gyro.bias for r in results])
    formal = pool_estimates(list(biases), [r.gyro.bias_sigma for r in results]).sigma
    scatter = biases.std(axis=0, ddof=1) / np.sqrt(len(biases)) if len(biases) > 1 else np.zeros(3)
    gyro_bias = Pooled(biases.mean(axis=0), np.maximum(formal, scatter), len(biases))
    spread = biases.std(axis=0, ddof=1) if len(biases) > 1 else np.zeros(3)
    c_sb = polar_decomposition(np.mean([g.c_sb for g in gyros], axis=0))[1] if gyros else np.eye(3)
    accels = [r.accel for r in results if r.accel.observable]
    mag_fits = [r.mag for r in results if r.mag is not None and r.mag.observable]
    k_matrix = None
    if mag_fits:
        k_matrix = np.mean([m.k_matrix for m in mag_fits], axis=0)
        k_matrix = k_matrix / np.cbrt(np.linalg.det(k_matrix))
    soft = _pool_field(mag_fits, "soft_iron", "soft_iron_sigma")

    all_rest = [(d, r) for d, r in zip(trials, results) if r.rest]
    dt = float(np.median([d.dt for d in trials]))
    gyro_noise = accel_noise = mag_noise = None
    if all_rest:
        segs = [(d, slice(p.start, p.stop)) for d, r in all_rest for p in r.rest]
        gyro_noise = sensor_noise([d.gyro[s] for d, s in segs], dt)
        accel_noise = sensor_noise([d.accel[s] for d, s in segs], dt)
        msegs = [d.mag[s] for d, s in segs if d.mag is not None and np.isfinite(d.mag[s]).all()]
        if msegs:
            mag_noise = sensor_noise(msegs, dt, tau_min_s=settings.mag_tau_min_s, markov=False)
    else:
        notes.append("no rest phase in any recording: noise terms not identified")

    offsets = [r.handling for r in results if r.handling is not None]
    arms = [r.lever_arm for r in results if r.lever_arm is not None]
    environments: list[MagneticEnvironment | None] = []
    for d, r in zip(trials, results):
        cal = r.mag if (r.mag is not None and r.mag.observable) else (mag_fits[0] if mag_fits else None)
        if d.mag is None or cal is None or r.mag_latency is None or not r.rest:
            environments.append(None)
            continue
        if cal is not r.mag:
            notes.append(f"{d.name}: magnetic environment with another trial's magnetometer calibration")
        body = cal.calibrated_body(d.mag)
        field_w = world_field(d.t, body, d.truth_t, d.q_wb, r.mag_latency.latency_s)
        rest_set = np.zeros(len(d.t), dtype=bool)
        for p in r.rest:
            rest_set[p.start : p.stop] = True
        movement = d.movement if d.movement is not None else ~rest_set
        pos = None
        if d.pos_w is not None:
            from .truth import interpolate_vectors

            pos = interpolate_vectors(d.truth_t, d.pos_w, d.t)
        r_bw = rotation_bw(interpolate_attitude(d.truth_t, d.q_wb, d.t - r.mag_latency.latency_s))
        try:
            environments.append(
                magnetic_environment(d.t, field_w, slice(r.rest[0].start, r.rest[0].stop), movement, pos, r_bw=r_bw)
            )
        except ValueError as e:
            notes.append(f"{d.name}: magnetic environment: {e}")
            environments.append(None)

    known = [(trial, env) for trial, env in zip(trials, environments) if env is not None]
    for odd in discordant_fields([env for _, env in known]):
        trial, env = known[odd.index]
        notes.append(
            f"{trial.name}: its field at rest ({env.norm * 1e6:.1f} uT, dip {np.degrees(env.dip):.1f} deg) lies "
            f"{odd.distance * 1e6:.1f} uT from the other recordings' median, beyond {FIELD_AGREEMENT:g} times the "
            f"field's spread along the paths ({odd.allowed * 1e6:.1f} uT): recorded elsewhere, or iron near its "
            "rest? The site's field pools it with the others; identify it alone, or leave it out"
        )
    scale = pool_random_effects([g.scale for g in gyros], [g.scale_sigma for g in gyros]) if gyros else None
    return Identification(
        trials=results,
        rate_hz=1.0 / dt,
        latency=latency,
        latency_bounds=frozenset(latency_bounds),
        gyro_bias=gyro_bias,
        gyro_bias_spread=spread,
        gyro_scale=scale[0] if scale is not None else None,
        gyro_scale_spread=scale[1] if scale is not None else None,
        gyro_misalignment=_pool_field(gyros, "misalignment", "misalignment_sigma") if gyros else None,
        c_sb=c_sb,
        accel_bias=pool_estimates([r.accel.bias for r in results], [r.accel.bias_sigma for r in results]),
        accel_scale=_pool_field(accels, "scale", "scale_sigma"),
        accel_cross_axis=_pool_field(accels, "cross_axis", "cross_axis_sigma") if accels else None,
        hard_iron=_pool_field(mag_fits, "hard_iron", "hard_iron_sigma"),
        soft_iron=soft,
        k_matrix=k_matrix,
        gyro_noise=gyro_noise,
        accel_noise=accel_noise,
        mag_noise=mag_noise,
        environments=environments,
        notes=notes,
        handling=pool_handling_offsets(offsets) if offsets else None,
        lever_arm=pool_estimates([a.lever_arm_b for a in arms], [a.lever_arm_sigma for a in arms]) if arms else None,
    )

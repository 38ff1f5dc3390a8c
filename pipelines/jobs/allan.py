"""``gyroemu allan``: fit the IEEE 952 noise terms to a static gyro log and draw the Allan plot.

:func:`allan_of_log` reads the log (an .mcap, or an .npz of ``gyroemu simulate``) and fits it;
:func:`write_allan_plot` draws the plot.

The fit is :func:`gyroemu.sensors.allan.fit_allan` over ``allantools``' overlapping Allan deviation, axis by
axis. The plot shows each axis's measured curve with its confidence band, the fitted model, and,
when the log carries its device's config, the specification's lines (quantisation, ARW, bias
instability floor, RRW) beside them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import numpy as np

from gyroemu.sensors.allan import AllanFit, allan_deviation, fit_allan
from gyroemu.sensors.errors import ErrorModel

__all__ = [
    "AllanLogError",
    "AllanReport",
    "allan_report",
    "allan_of_log",
    "plot_allan",
    "write_allan_plot",
    "SPEC_UNITS",
]

_DEG = 180.0 / np.pi
SPEC_UNITS = {  # term: (SI to datasheet factor, datasheet unit)
    "quantisation": (1.0, "rad"),
    "arw": (_DEG * 60.0, "deg/sqrt(h)"),
    "bias_instability": (_DEG * 3600.0, "deg/h"),
    "rrw": (_DEG * 3600.0 * 60.0, "deg/h/sqrt(h)"),
    "rate_ramp": (_DEG * 3600.0 * 3600.0, "deg/h/h"),
}


@dataclass(frozen=True)
class AllanReport:
    """Fits of the three axes of a gyro log, and the specification they are compared with."""

    fits: tuple[AllanFit, AllanFit, AllanFit]
    spec: ErrorModel | None
    intrinsic_noise_density: float = 0.0

    def table(self) -> str:
        """A plain-text table: each term's fitted value per axis (datasheet units) and the spec."""
        lines = [f"{'term':<17}{'unit':<15}{'x':>12}{'y':>12}{'z':>12}{'spec':>12}"]
        specified = _spec_terms(self.spec) if self.spec is not None else {}
        for term, (factor, unit) in SPEC_UNITS.items():
            values = [getattr(f, term).value * factor for f in self.fits]
            spec = specified.get(term)
            spec_text = f"{spec * factor:12.4g}" if spec is not None else f"{'-':>12}"
            lines.append(f"{term:<17}{unit:<15}" + "".join(f"{v:12.4g}" for v in values) + spec_text)
        return "\n".join(lines)


def _spec_terms(spec: ErrorModel) -> dict:
    """The specification's Allan coefficients in SI (axis x; presets give the same for all axes)."""
    q = spec.integral_lsb / np.sqrt(12) if spec.integral_lsb else None
    return {
        "quantisation": q,
        "arw": float(spec.noise_density[0]),
        "bias_instability": float(spec.bias_instability[0]),
        "rrw": float(spec.random_walk[0]),
        "rate_ramp": float(spec.ramp[0]) or None,
    }


def allan_report(gyro: np.ndarray, dt: float, spec: ErrorModel | None = None) -> AllanReport:
    """Fit each axis of a static gyro record ``gyro`` (N, 3), rad/s, sampled every ``dt`` s."""
    gyro = np.asarray(gyro, dtype=float)
    if gyro.ndim != 2 or gyro.shape[1] != 3 or len(gyro) < 64:
        raise ValueError(f"an Allan analysis needs a (N, 3) gyro record with N >= 64, got shape {gyro.shape}")
    if not np.all(np.isfinite(gyro)):
        raise ValueError("the gyro record has NaN or infinite samples")
    fits = cast(  # one per axis: three
        tuple[AllanFit, AllanFit, AllanFit],
        tuple(fit_allan(allan_deviation(gyro[:, i] - gyro[:, i].mean(), dt)) for i in range(3)),
    )
    return AllanReport(fits=fits, spec=spec)


class AllanLogError(ValueError):
    """A log :func:`allan_of_log` cannot analyse: missing, not a gyroemu log, no or too few gyro samples.
    The message starts with the file's name."""


def _read_gyro(log: Path) -> tuple[np.ndarray, np.ndarray, str | None]:
    """``(gyro (N, 3) rad/s, t (N,) s, device TOML or None)`` of an .mcap or .npz log."""
    if log.suffix == ".mcap":
        from gyroemu.pipelines.formats.mcap_log import read_mcap

        device_log = read_mcap(log).device
        device_toml = (device_log.metadata or {}).get("device") or None
        return device_log.samples.gyro, device_log.samples.t, device_toml
    try:
        with np.load(log, allow_pickle=False) as data:
            if "imu/gyro" not in data or "imu/t" not in data:
                gyro = None
            else:
                gyro, t = data["imu/gyro"], data["imu/t"]
                device_toml = str(data["device_toml"]) if "device_toml" in data else None
    except (OSError, ValueError) as e:
        raise AllanLogError(f"{log}: not a gyroemu log (.mcap or .npz): {e}") from None
    if gyro is None:
        raise AllanLogError(f"{log}: holds no gyro samples (write one with 'gyroemu simulate --device ...')")
    return gyro, t, device_toml


def allan_of_log(path: str | os.PathLike) -> AllanReport:
    """Fit a static gyro log: an .mcap (its device, with the device's config when the log carries it),
    or an .npz of ``gyroemu simulate --device`` (``imu/gyro``, ``imu/t``, ``device_toml``). The sample
    interval is the median step of the stamps. Raises :class:`AllanLogError` for a log it cannot use,
    :class:`gyroemu.errors.LogError` for an .mcap it cannot read."""
    log = Path(path)
    if not log.is_file():
        raise AllanLogError(f"{log}: no such file")
    gyro, t, device_toml = _read_gyro(log)
    spec = None
    if device_toml is not None:
        import dataclasses
        import tomllib

        from gyroemu.sensors import device_from_dict

        device = device_from_dict(tomllib.loads(device_toml), name=log.name)
        spec = dataclasses.replace(device.gyro_errors, noise_density=device.gyro_noise_density)
    dt = float(np.median(np.diff(t)))
    try:
        return allan_report(gyro, dt, spec)
    except ValueError as e:
        raise AllanLogError(f"{log}: {e}") from None


def write_allan_plot(report: AllanReport, out: str | os.PathLike, title: str = "") -> Path:
    """:func:`plot_allan` to ``out`` (a PNG whatever its suffix) through a temporary file beside it, so
    that no partial plot is left; returns ``out``."""
    out = Path(out)
    tmp = out.with_name(f".{out.name}.tmp.png")
    try:
        plot_allan(report, tmp, title=title)
        tmp.replace(out)
    finally:
        tmp.unlink(missing_ok=True)
    return out


def plot_allan(report: AllanReport, out: str | Path, title: str = "") -> Path:
    """Draw the Allan plot (PNG): measured curves with 68 % bands, fitted models, specification lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.5), dpi=110)
    to_deg_h = _DEG * 3600.0
    for axis, (fit, colour) in enumerate(zip(report.fits, ("tab:red", "tab:green", "tab:blue"))):
        a = fit.allan
        ax.fill_between(a.tau, a.low * to_deg_h, a.high * to_deg_h, color=colour, alpha=0.15, lw=0)
        ax.loglog(a.tau, a.adev * to_deg_h, "o", ms=3, color=colour, label=f"measured {'xyz'[axis]}")
        ax.loglog(a.tau, fit.model(a.tau) * to_deg_h, "-", lw=1, color=colour, alpha=0.8)
    tau = report.fits[0].allan.tau
    if report.spec is not None:
        s = _spec_terms(report.spec)
        lines = {
            "spec quantisation": None if s["quantisation"] is None else np.sqrt(3) * s["quantisation"] / tau,
            "spec ARW": s["arw"] / np.sqrt(tau) if s["arw"] else None,
            "spec bias instability": np.full_like(tau, 0.664 * s["bias_instability"])
            if s["bias_instability"]
            else None,
            "spec RRW": s["rrw"] * np.sqrt(tau / 3) if s["rrw"] else None,
        }
        for (label, values), style in zip(lines.items(), ((0, (1, 3)), "--", "-.", ":")):
            if values is not None:
                ax.loglog(tau, values * to_deg_h, color="0.3", ls=style, lw=1.2, label=label)
    lowest = min(float(f.allan.adev.min()) for f in report.fits) * to_deg_h
    ax.set_ylim(bottom=lowest / 5)  # spec lines below the data would only squash the curves
    ax.set_xlabel("averaging time τ (s)")
    ax.set_ylabel("Allan deviation (deg/h)")
    ax.set_title(title or "Allan deviation")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    out = Path(out)
    fig.savefig(out)
    plt.close(fig)
    return out

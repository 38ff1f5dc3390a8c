"""The report of ``gyroemu twin``: each recording beside its twins (filters' errors, the rankings they
give, the residuals at rest) as ``twin.md``, ``twin.json`` and one plot per recording.

Outputs in ``--out``: ``twin.md``, ``twin.json`` and ``<trial>.png`` (Allan deviations and spectra, real
against twin), all or none: each written to a temporary file, and all renamed into place once all are
complete (:func:`~gyroemu.pipelines.formats.atomic.staged_files`), so a full disk at the last plot leaves
``--out`` as it was.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, SupportsFloat

import numpy as np

from .motion import twin_seed
from .recording import Recording
from .residuals import TAUS_S, rms_over_seeds
from .runs import METRICS, counted_samples

if TYPE_CHECKING:
    from gyroemu.pipelines.formats.atomic import StagedFiles

__all__ = ["RANKED_FILTERS", "TrialResult", "TwinReport", "trial_result", "format_vector"]

RANKED_FILTERS = ("mekf", "vqf", "madgwick", "mahony")
"""The filters whose order by 9D total the real recording and its twins are compared on."""


def format_vector(v: np.ndarray) -> str:
    """``(x, y, z)`` with four significant digits each."""
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"


def _finite(x: SupportsFloat | None) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _list(a: np.ndarray, digits: int = 6) -> list[Any]:
    return [_list(v, digits) if np.ndim(v) else _finite(float(f"{v:.{digits}g}")) for v in np.asarray(a)]


@dataclass
class TrialResult:
    """One recording beside its twins."""

    name: str
    source: dict[str, Any]
    mode: str
    rate_hz: float
    twin_rate_hz: float
    t0_s: float
    rest: dict[str, Any]
    filters: list[dict[str, Any]]
    ranking: dict[str, Any]
    residuals: dict[str, Any]
    curves: dict[str, Any]  # for the plot: real and twin Allan deviations and spectra
    notes: list[str] = field(default_factory=list)


@dataclass
class TwinReport:
    """What :func:`run_twin` found."""

    trials: list[TrialResult]
    settings: dict[str, Any]
    timings: dict[str, Any]
    notes: list[str] = field(default_factory=list)
    pooled_residuals: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "gyroemu_twin": 1,
            "settings": self.settings,
            "definitions": {
                "errors": "BROAD: q_err = q_est ⊗ conj(q_true); total 2 acos|w|, heading 2 atan|z/w|, "
                "inclination 2 acos sqrt(w²+z²); RMSE in degrees over the movement samples with a finite "
                "reference (twins: the real mask at the nearest real sample, real time = twin time + t0)",
                "twin": "mean, std (ddof 1), n over the seeds whose run gave a finite value; values per seed",
                "ratio": "twin mean / real",
                "ranking": f"order of {', '.join(RANKED_FILTERS)} by 9D total RMSE, real and twin mean; "
                "unresolved: pairs whose paired seed differences are not significant (Student t, 5 %); "
                "same_within_spread: every pair the twin swaps is unresolved",
                "residuals": "measured − truth over the rest phases, pooled; Allan deviation per axis (x, y, z) "
                "at tau_s, twin: RMS over seeds; ratio twin/real per tau and axis; psd_ratio: median over "
                "1 Hz … rate/4 of the twin's mean Welch spectrum over the real's, per axis",
            },
            "timings_s": self.timings,
            "notes": self.notes,
            "residuals_pooled": None
            if self.pooled_residuals is None
            else {
                k: (_list(v) if k == "tau_s" else {name: _list(arr) for name, arr in v.items()})
                for k, v in self.pooled_residuals.items()
            },
            "trials": [
                {
                    "name": tr.name,
                    "source": tr.source,
                    "mode": tr.mode,
                    "rate_hz": tr.rate_hz,
                    "twin_rate_hz": tr.twin_rate_hz,
                    "t0_s": tr.t0_s,
                    "rest": tr.rest,
                    "filters": tr.filters,
                    "ranking": tr.ranking,
                    "residuals": tr.residuals,
                    "notes": tr.notes,
                }
                for tr in self.trials
            ],
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1, ensure_ascii=False, allow_nan=False)

    def to_markdown(self) -> str:
        s = self.settings
        lines = [
            "# gyroemu twin",
            "",
            f"Device `{s['device']}`, {s['seeds']} twin(s) per recording (twin i's device, magnetic environment "
            f"and handling seeded by twin_seed(i, file name), i = 0…{s['seeds'] - 1}), site `{s['site']}`. "
            "Twin: mean ± standard deviation over the seeds; "
            "ratio: twin mean / real. RMSE in degrees (BROAD's definitions) over the movement samples.",
            "",
        ]
        for tr in self.trials:
            lines += [f"## {tr.name} ({tr.mode})", ""]
            lines.append(
                "| filter | 9D total real | 9D total twin | ratio | 9D heading real | 9D heading twin | ratio "
                "| 9D inclination real | 9D inclination twin | ratio | 6D inclination real | 6D inclination twin "
                "| ratio |"
            )
            lines.append("|---|" + "---|" * 12)
            for fr in tr.filters:
                cells = [fr["filter"]]
                for m in METRICS:
                    real = fr["real"][m]
                    tw = fr["twin"][m]
                    cells.append("—" if real is None else f"{real:.2f}")
                    if tw["mean"] is None:
                        cells.append("—")
                    else:
                        cells.append(f"{tw['mean']:.2f} ± {tw['std']:.2f}" if tw["n"] > 1 else f"{tw['mean']:.2f}")
                    cells.append("—" if fr["ratio"][m] is None else f"{fr['ratio'][m]:.2f}")
                lines.append("| " + " | ".join(cells) + " |")
            lines.append("")
            rk = tr.ranking
            if rk["same"] is None:
                lines.append(f"Ranking by 9D total: not available ({rk.get('why', '')}).")
            else:
                if rk["same"]:
                    verdict = "**same**."
                elif rk["same_within_spread"]:
                    verdict = "**differs** within the seeds' spread (every swapped pair unresolved at 5 %)."
                else:
                    verdict = "**differs** beyond the seeds' spread."
                lines.append(
                    f"Ranking by 9D total: real {' < '.join(rk['real'])}; twin {' < '.join(rk['twin'])} — " + verdict
                )
            rest = tr.rest
            lines.append("")
            spans = ", ".join(f"{a:.2f}…{b:.2f}" for a, b in rest["intervals_s"])
            lines.append(
                f"Residuals at rest ({rest['source']}: {spans} s of the recording, "
                f"{rest['real_samples']} real samples):"
            )
            lines.append("")
            lines.append(
                "| sensor | real std (x, y, z) | twin std (x, y, z) | Allan ratio twin/real min … max "
                "| PSD ratio (x, y, z) |"
            )
            lines.append("|---|---|---|---|---|")
            for key, unit in (("gyro", "°/s"), ("accel", "m/s²")):
                r = tr.residuals[key]
                scale = math.degrees(1.0) if key == "gyro" else 1.0

                def fmt(v: float | None, scale: float = scale) -> str:
                    return "—" if v is None else f"{v * scale:.3g}"

                ratio = (
                    "—"
                    if r["ratio_min"] is None
                    else f"{r['ratio_min']:.2f} … {r['ratio_max']:.2f} (τ {r['tau_min_s']:.2g}…{r['tau_max_s']:.2g} s)"
                )
                psd = ", ".join("—" if v is None else f"{v:.2f}" for v in r["psd_ratio"])
                lines.append(
                    f"| {key} | {', '.join(fmt(v) for v in r['real_std'])} {unit} | "
                    f"{', '.join(fmt(v) for v in r['twin_std'])} {unit} | {ratio} | {psd} |"
                )
            for n in tr.notes:
                lines.append(f"- {n}")
            lines.append("")
        if self.pooled_residuals is not None and len(self.trials) > 1:
            lines += [f"## Residuals at rest, pooled over the {len(self.trials)} recordings", ""]
            lines += [
                "| sensor | Allan ratio twin/real min … max, τ 0.01…10 s | real clusters at 10 s |",
                "|---|---|---|",
            ]
            for key in ("gyro", "accel"):
                r = self.pooled_residuals[key]
                pooled_ratio = np.asarray(r["ratio"], dtype=float)
                kept = pooled_ratio[np.isfinite(pooled_ratio)]
                span = f"{kept.min():.2f} … {kept.max():.2f}" if kept.size else "—"
                lines.append(f"| {key} | {span} | {int(np.min(r['real_clusters'][-1]))} |")
            lines.append("")
        lines.append(
            "Timings (s, summed over processes): " + ", ".join(f"{k} {v:.1f}" for k, v in self.timings.items())
        )
        if self.notes:
            lines += ["", "Notes:"] + [f"- {n}" for n in self.notes]
        return "\n".join(lines) + "\n"

    def save_plots(self, directory: str | os.PathLike[str]) -> list[Path]:
        """One ``<trial>.png`` per recording in ``directory``; all or none of them."""
        from gyroemu.pipelines.formats.atomic import staged_files

        with staged_files() as stage:
            return self._stage_plots(stage, Path(directory))

    def _stage_plots(self, stage: StagedFiles, directory: Path) -> list[Path]:
        """:meth:`save_plots` through ``stage``."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from gyroemu.pipelines.formats.file_names import unique_stems

        written = []
        for tr, stem in zip(self.trials, unique_stems([Path(t.name).stem for t in self.trials])):
            fig, axes = plt.subplots(2, 2, figsize=(11, 7.5))
            colours = ("C0", "C1", "C2")
            for col, (key, unit, scale) in enumerate((("gyro", "°/s", math.degrees(1.0)), ("accel", "m/s²", 1.0))):
                c = tr.curves[key]
                ax = axes[0, col]
                for axis in range(3):
                    ax.loglog(
                        TAUS_S, c["real_adev"][:, axis] * scale, "-", color=colours[axis], label=f"real {'xyz'[axis]}"
                    )
                    ax.loglog(
                        TAUS_S, c["twin_adev"][:, axis] * scale, "--", color=colours[axis], label=f"twin {'xyz'[axis]}"
                    )
                ax.set_title(f"{key} residual at rest: Allan deviation")
                ax.set_xlabel("τ, s")
                ax.set_ylabel(unit)
                ax.grid(True, which="both", alpha=0.3)
                ax.legend(fontsize=7, ncol=2)
                ax = axes[1, col]
                for axis in range(3):
                    if len(c["real_f"]):
                        ax.semilogy(c["real_f"], c["real_psd"][:, axis] * scale**2, "-", color=colours[axis], lw=0.8)
                    if len(c["twin_f"]):
                        ax.semilogy(c["twin_f"], c["twin_psd"][:, axis] * scale**2, "--", color=colours[axis], lw=0.8)
                ax.set_title(f"{key} residual at rest: spectrum (solid real, dashed twin)")
                ax.set_xlabel("Hz")
                ax.set_ylabel(f"({unit})²/Hz")
                ax.grid(True, which="both", alpha=0.3)
            fig.suptitle(f"{tr.name}: real vs twin ({self.settings['device']}, {self.settings['seeds']} seeds)")
            fig.tight_layout()
            path = directory / f"{stem}.png"
            written.append(stage.write_figure(fig, path, dpi=100))
        return written

    def save(self, directory: str | os.PathLike[str]) -> dict[str, Any]:
        """``twin.md``, ``twin.json`` and the plots in ``directory`` (made if missing); their paths. All or
        nothing: each file is written to a temporary file, and they are renamed into place only once all
        are complete; on an error (a full disk) ``directory`` is left as it was."""
        from gyroemu.pipelines.formats.atomic import staged_files

        directory = Path(directory)
        paths: dict[str, Any] = {"markdown": directory / "twin.md", "json": directory / "twin.json"}
        with staged_files(directory) as stage:
            stage.write_text(paths["json"], self.to_json())
            stage.write_text(paths["markdown"], self.to_markdown())
            paths["plots"] = self._stage_plots(stage, directory)
        return paths


def _summary(values: list[float | None]) -> dict[str, Any]:
    finite = [float(v) for v in values if v is not None and math.isfinite(v)]
    return {
        "mean": float(np.mean(finite)) if finite else None,
        "std": float(np.std(finite, ddof=1)) if len(finite) > 1 else None,  # ddof 1: none for one value
        "n": len(finite),
        "values": [_finite(v) for v in values],
    }


def _rank(values: dict[str, Any]) -> list[str]:
    return sorted(values, key=lambda f: values[f])


def _discordant_pairs(real: list[str], twin: list[str]) -> list[list[str]]:
    """Pairs ``[a, b]`` (``a`` before ``b`` on the real ranking) that the twin ranking orders the other way."""
    return [[a, b] for i, a in enumerate(real) for b in real[i + 1 :] if twin.index(a) > twin.index(b)]


def _unresolved_pairs(real: list[str], means: dict[str, Any], seeds: dict[str, Any]) -> list[list[str]]:
    """Pairs of filters whose twin mean 9D totals the seeds cannot tell apart: the seeds share their
    data, so the paired differences ``d_s`` are tested, ``|mean d| < t_{0.975, n−1} · sd(d)/√n``
    (Student's t, two-sided 5 %). Listed in the real ranking's order."""
    from scipy.stats import t as student_t

    out = []
    for i, a in enumerate(real):
        for b in real[i + 1 :]:
            d = np.array([x - y for x, y in zip(seeds[a], seeds[b], strict=True) if x is not None and y is not None])
            if len(d) < 2:
                out.append([a, b])  # one seed cannot order them
                continue
            bound = float(student_t.ppf(0.975, len(d) - 1)) * float(np.std(d, ddof=1)) / np.sqrt(len(d))
            if abs(float(np.mean(d))) < bound:
                out.append([a, b])
    return out


def trial_result(
    real: Recording,
    real_run: dict[str, Any],
    twins: list[dict[str, Any]],
    filters: list[str],
    mode: str,
    rest: dict[str, Any],
    seeds: int,
    twin_rate: float,
) -> TrialResult:
    """The recording ``real`` beside its ``twins``: the runs of :func:`~.runs.run_real` and
    :func:`~.runs.run_one_twin` (seeds 0 … ``seeds`` − 1) summarised per filter, the rankings, the
    residuals' ratios, and the notes; ``mode`` "9D" or "6D", ``rest`` :func:`~.recording.rest_phases`'s
    description, ``twin_rate`` the device's rate, Hz."""
    rows: list[dict[str, Any]] = []
    for spec in filters:
        r = real_run["errors"][spec]
        tw = {m: _summary([tr["errors"][spec][m] for tr in twins]) for m in METRICS}
        ratio = {
            m: (tw[m]["mean"] / r[m] if tw[m]["mean"] is not None and _finite(r[m]) and r[m] > 0 else None)
            for m in METRICS
        }
        errs = [e for e in [r.get("error")] + [tr["errors"][spec].get("error") for tr in twins] if e]
        rows.append(
            {
                "filter": spec,
                "real": {m: _finite(r[m]) for m in METRICS},
                "twin": tw,
                "ratio": ratio,
                "errors": errs,
            }
        )
    ranked = [f for f in RANKED_FILTERS if f in filters]
    ranking: dict[str, Any] = {
        "filters": ranked,
        "real": None,
        "twin": None,
        "same": None,
        "same_within_spread": None,
        "unresolved": [],
    }
    if mode != "9D":
        ranking["why"] = "6D only"
    elif len(ranked) < 2:
        ranking["why"] = f"fewer than two of {', '.join(RANKED_FILTERS)}"
    else:
        by = {row["filter"]: row for row in rows}
        real_v = {f: by[f]["real"]["total_9d"] for f in ranked}
        twin_v = {f: by[f]["twin"]["total_9d"]["mean"] for f in ranked}
        if any(v is None for v in real_v.values()) or any(v is None for v in twin_v.values()):
            ranking["why"] = "a filter without a 9D total"
        else:
            ranking.update(real=_rank(real_v), twin=_rank(twin_v))
            ranking["same"] = ranking["real"] == ranking["twin"]
            seeds_9d = {f: by[f]["twin"]["total_9d"]["values"] for f in ranked}
            ranking["unresolved"] = _unresolved_pairs(ranking["real"], twin_v, seeds_9d)
            discordant = _discordant_pairs(ranking["real"], ranking["twin"])
            ranking["same_within_spread"] = all(pair in ranking["unresolved"] for pair in discordant)
    residuals: dict[str, Any] = {"tau_s": _list(TAUS_S, 4)}
    curves: dict[str, Any] = {}
    rr = real_run["residuals"]
    for key in ("gyro", "accel"):
        real_adev = rr[f"{key}_adev"]
        twin_adev = rms_over_seeds([t["residuals"][f"{key}_adev"] for t in twins])
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = twin_adev / real_adev
        ok = np.isfinite(ratio)
        taus_ok = TAUS_S[ok.any(axis=1)]
        psd_ratio: list[float | None] = [None, None, None]
        f_real, p_real = rr[f"{key}_psd_f"], rr[f"{key}_psd"]
        twin_p = [t["residuals"][f"{key}_psd"] for t in twins if len(t["residuals"][f"{key}_psd_f"])]
        f_twin = twins[0]["residuals"][f"{key}_psd_f"]
        p_twin = np.mean(np.stack(twin_p), axis=0) if twin_p and all(len(p) == len(twin_p[0]) for p in twin_p) else None
        if len(f_real) and p_twin is not None:
            band = (f_real >= 1.0) & (f_real <= min(real.rate_hz, twin_rate) / 4)  # within both Nyquists
            if band.any():
                interp = np.stack([np.interp(f_real[band], f_twin, p_twin[:, a]) for a in range(3)], axis=1)
                with np.errstate(invalid="ignore", divide="ignore"):
                    psd_ratio = [_finite(v) for v in np.median(interp / p_real[band], axis=0)]
        residuals[key] = {
            "unit": "rad/s" if key == "gyro" else "m/s²",
            "real_adev": _list(real_adev),
            "twin_adev": _list(twin_adev),
            "ratio": _list(ratio, 4),
            "ratio_min": _finite(np.min(ratio[ok])) if ok.any() else None,
            "ratio_max": _finite(np.max(ratio[ok])) if ok.any() else None,
            "tau_min_s": _finite(taus_ok.min()) if len(taus_ok) else None,
            "tau_max_s": _finite(taus_ok.max()) if len(taus_ok) else None,
            "real_std": _list(rr[f"{key}_std"]),
            "twin_std": _list(np.mean(np.stack([t["residuals"][f"{key}_std"] for t in twins]), axis=0)),
            "psd_ratio": psd_ratio,
        }
        curves[key] = {
            "real_adev": real_adev,
            "twin_adev": twin_adev,
            "real_f": f_real,
            "real_psd": p_real,
            "twin_f": f_twin if p_twin is not None else np.zeros(0),
            "twin_psd": p_twin if p_twin is not None else np.zeros((0, 3)),
        }
    rest = dict(rest)
    rest["real_samples"] = int(rr["samples"])
    rest["twin_samples"] = [int(t["residuals"]["samples"]) for t in twins]
    counted = counted_samples(real.mask, real.q_true)
    notes = [
        f"real: {int(counted.sum())} samples counted ({real.counted}); twins: "
        + ", ".join(str(t["counted"]) for t in twins)
    ]
    drawn = [t.get("handling_offset") for t in twins]
    if any(d is not None for d in drawn):
        notes.append(
            "handling offsets over the movement, m/s² (x, y, z) per seed: "
            + "; ".join("none" if d is None else format_vector(np.asarray(d)) for d in drawn)
        )
    for row in rows:
        for e in row["errors"]:
            notes.append(f"{row['filter']} failed: {e}")
    return TrialResult(
        name=real.name,
        source={
            "path": str(real.path),
            "format": real.format,
            "seeds": list(range(seeds)),
            "twin_seeds": [twin_seed(i, real.name, real.same_name_index) for i in range(seeds)],
        },
        mode=mode,
        rate_hz=real.rate_hz,
        twin_rate_hz=twin_rate,
        t0_s=float(twins[0]["t0"]),
        rest=rest,
        filters=rows,
        ranking=ranking,
        residuals=residuals,
        curves=curves,
        notes=notes,
    )

"""The ``recorded`` scenario kind: a recorded motion (a motion capture, a dataset's ground truth, a
log's truth) as the truth an emulated device senses.

A scenario file::

    kind = "recorded"
    path = "walk.tum"              # absolute, or relative to the scenario file
    format = "tum"                 # mcap, broad, tum or csv (gyroemu.pipelines.formats.motion_files)
    time_offset_s = 0.0            # scenario time 0 is this far after the first valid sample
    # duration_s = 60.0            # default: the rest of the recording
    # rate_hz = 1000.0             # default: the device's rate (simulate), else the recording's
    # world_to_enu_quat = [w, x, y, z]   # turns the file's world axes into ENU (default: it is ENU)

    [smoothing]                    # all optional: GCV chooses the smoothing from the data
    position_noise_m = 1e-4        # a stated noise level chooses it by the unbiased risk instead
    orientation_noise_deg = 0.05
    # position_cutoff_hz, orientation_cutoff_hz: where the gain is 1/2 (a reference with coloured noise)
    # position_lambda_s3, orientation_lambda_s3: λ outright
    max_gap_s = 0.25               # a longer gap without valid samples is an error

    [site]                         # where the motion took place (gyroemu.dynamics.earth.Site)

The file is read and checked when the scenario is loaded (errors name the file and the line, before any
work); the splines are fitted on the first :meth:`RecordedSpec.trajectory`
(:class:`gyroemu.dynamics.recorded.RecordedMotion`).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import PrivateAttr, field_validator

from gyroemu.dynamics.config import NonNegativeReal, PositiveReal, Quat, Section
from gyroemu.dynamics.earth import Site
from gyroemu.dynamics.recorded import MotionSamples, RecordedMotion, RecordedMotionError, SmoothingOptions
from gyroemu.dynamics.scenarios import Duration, Rate, ScenarioSpec
from gyroemu.dynamics.trajectory import Trajectory
from gyroemu.errors import ConfigError

__all__ = ["SmoothingSpec", "RecordedSpec"]


class SmoothingSpec(Section):
    """``[smoothing]`` of a recorded scenario (see :class:`gyroemu.dynamics.recorded.SmoothingOptions`)."""

    position_noise_m: PositiveReal | None = None
    orientation_noise_deg: PositiveReal | None = None
    position_cutoff_hz: PositiveReal | None = None
    orientation_cutoff_hz: PositiveReal | None = None
    position_lambda_s3: NonNegativeReal | None = None
    orientation_lambda_s3: NonNegativeReal | None = None
    max_gap_s: PositiveReal = 0.25

    def options(self) -> SmoothingOptions:
        return SmoothingOptions(
            position_noise_m=self.position_noise_m,
            orientation_noise_rad=None
            if self.orientation_noise_deg is None
            else math.radians(self.orientation_noise_deg),
            position_lambda=self.position_lambda_s3,
            orientation_lambda=self.orientation_lambda_s3,
            max_gap_s=self.max_gap_s,
            position_cutoff_hz=self.position_cutoff_hz,
            orientation_cutoff_hz=self.orientation_cutoff_hz,
        )


class RecordedSpec(ScenarioSpec):
    """A ``kind = "recorded"`` scenario file (module notes)."""

    kind: Literal["recorded"]
    pointwise: ClassVar[bool] = True  # the truth is a closed form in t
    duration_s: Duration | None = None  # type: ignore[assignment]
    rate_hz: Rate | None = None  # type: ignore[assignment]
    path: str
    format: Literal["mcap", "broad", "tum", "csv"]
    time_offset_s: NonNegativeReal = 0.0
    world_to_enu_quat: Quat | None = None
    smoothing: SmoothingSpec = SmoothingSpec()
    site: Site = Site()

    _samples: MotionSamples | None = PrivateAttr(default=None)
    _motion: RecordedMotion | None = PrivateAttr(default=None)
    _file: str | Path | None = PrivateAttr(default=None)

    @field_validator("world_to_enu_quat")
    @classmethod
    def _a_rotation(cls, q: tuple[float, float, float, float] | None) -> tuple[float, float, float, float] | None:
        if q is not None and not math.sqrt(sum(c * c for c in q)) > 1e-9:
            raise ValueError("a rotation's quaternion is not zero (w, x, y, z; normalised when read)")
        return q

    def __eq__(self, other: object) -> bool:
        """Equal configs (the loaded recording, a cache, does not count)."""
        return isinstance(other, RecordedSpec) and type(other) is type(self) and self.model_dump() == other.model_dump()

    def __hash__(self) -> int:
        return hash(self.model_dump_json())

    @classmethod
    def prepare(cls, data: dict[str, Any], path: Path | None) -> dict[str, Any]:
        """``data`` with a relative ``path`` made absolute against the scenario file's folder."""
        source = data.get("path")
        if isinstance(source, str) and path is not None and not Path(source).is_absolute():
            data = {**data, "path": str((path.parent / source).resolve())}
        return data

    def load(self, file: str | Path | None = None) -> None:
        """Read and check the recording now (:class:`ConfigError` naming the scenario ``file``, the key and
        the recording's file and line)."""
        from gyroemu.pipelines.formats.motion_files import read_motion

        if self._samples is not None:
            return
        self._file = file
        source = Path(self.path)
        if not source.is_file():
            reason = f"{source}: no such file" if not source.exists() else f"{source}: not a file"
            raise ConfigError(reason, file=file, key="path")
        try:
            samples = read_motion(source, self.format, self.world_to_enu_quat)
            samples.check()
        except RecordedMotionError as e:
            raise ConfigError(str(e), file=file, key="path") from None
        self._samples = samples
        valid = samples.t[samples.valid()]
        span = float(valid[-1] - valid[0])
        if self.time_offset_s >= span:
            raise ConfigError(
                f"{self.time_offset_s:g} s is not inside the recording's {span:.6g} s", file=file, key="time_offset_s"
            )
        if self.duration_s is not None and self.time_offset_s + self.duration_s > span * (1 + 1e-9):
            raise ConfigError(
                f"{self.duration_s:g} s from time_offset_s = {self.time_offset_s:g} s runs past the end of the "
                f"recording ({span:.6g} s)",
                file=file,
                key="duration_s",
            )

    def replace_attitude(self, t: ArrayLike, q_wb: ArrayLike) -> None:
        """Take the attitude ``q_wb`` (M, 4) at stamps ``t`` (M,, the recording's clock; NaN rows where
        missing) as the recording's before the motion is fitted: e.g. the reference refined by the
        recording's own gyro (:func:`gyroemu.dynamics.attitude_fusion.complementary_attitude`). It is
        interpolated (Slerp; a stamp of ``t`` gives its own row) onto the recording's samples that have an
        attitude and lie within ``t``'s valid span; the others lose theirs. :class:`ValueError` once the
        motion is fitted, or for shapes that do not match."""
        from gyroemu.dynamics.rotation import quat_interpolate

        self.load()
        assert self._samples is not None
        if self._motion is not None:
            raise ValueError("the motion is fitted already: replace the attitude before the first trajectory")
        t = np.asarray(t, dtype=float)
        q = np.asarray(q_wb, dtype=float)
        if t.ndim != 1 or q.shape != (len(t), 4):
            raise ValueError(f"t (M,) and q_wb (M, 4) are needed, got {t.shape} and {q.shape}")
        ok = np.isfinite(t) & np.isfinite(q).all(axis=1)
        if ok.sum() < 2:
            raise ValueError("q_wb needs at least two valid rows")
        stamps = self._samples.t
        had = np.isfinite(self._samples.q_wb).all(axis=1)
        inside = had & (stamps >= t[ok][0]) & (stamps <= t[ok][-1])
        replaced = np.full(self._samples.q_wb.shape, np.nan)
        replaced[inside] = quat_interpolate(t[ok], q[ok], stamps[inside])
        self._samples = dataclasses.replace(self._samples, q_wb=replaced)
        self._samples.check()

    def motion(self) -> RecordedMotion:
        """The smoothed motion (fitted on first use)."""
        if self._motion is None:
            self.load()
            assert self._samples is not None
            try:
                self._motion = RecordedMotion(self._samples, self.smoothing.options())
            except RecordedMotionError as e:  # a gap or a cut-off: the key at fault
                key = f"smoothing.{e.key}" if e.key else "smoothing"
                raise ConfigError(str(e), file=self._file, key=key) from None
        return self._motion

    def max_span_s(self) -> float:
        """From ``time_offset_s`` to the last valid sample, s."""
        self.load()
        assert self._samples is not None
        valid = self._samples.t[self._samples.valid()]
        return float(valid[-1] - valid[0]) - self.time_offset_s

    def span_s(self) -> float:
        return self.duration_s if self.duration_s is not None else self.max_span_s()

    def default_rate_hz(self) -> float:
        if self.rate_hz is not None:
            return self.rate_hz
        self.load()
        assert self._samples is not None
        return float(1.0 / np.median(np.diff(self._samples.t[self._samples.valid()])))

    def report(self) -> str:
        """The smoothing chosen and the gaps bridged (empty before the motion is fitted)."""
        motion = self._motion
        if motion is None:
            return ""
        sm = self.smoothing
        if sm.orientation_lambda_s3 is not None or sm.orientation_cutoff_hz is not None:
            chosen = "given"
        else:
            chosen = "unbiased risk" if sm.orientation_noise_deg is not None else "GCV"
        parts = [f"recorded motion {Path(self.path).name}: {motion.duration:.6g} s at {motion.rate_hz:.6g} Hz"]
        parts.append(f"attitude smoothed to {motion.orientation_cutoff_hz:.3g} Hz ({chosen})")
        if motion.has_position:
            parts.append(f"position to {motion.position_cutoff_hz:.3g} Hz")
        else:
            parts.append("no position recorded: the body is held at the origin")
        parts.append(str(motion.gaps))
        return "; ".join(parts)

    def trajectory(self, t: NDArray[np.float64]) -> Trajectory:
        """The truth at scenario times ``t`` (s; motion time ``t + time_offset_s``), stamped ``t``."""
        motion = self.motion()
        traj = motion.trajectory(np.asarray(t, dtype=float) + self.time_offset_s, self.site.environment())
        if self.time_offset_s:
            import dataclasses

            traj = dataclasses.replace(traj, t=np.asarray(t, dtype=float).copy())
        return traj

"""A twin's motion and its draws: the recording's truth as the ``recorded`` scenario smooths it, its
attitude refined by the recording's own gyro, and the seed each twin of a recording draws from.

A **twin** of a recording is its own recorded motion sensed by an emulated device in the modelled
field of a site. The motion is the recording's truth as the ``recorded`` scenario kind smooths it
(:mod:`gyroemu.pipelines.recorded_scenario`), its attitude first refined by the recording's own gyro
above :data:`TWIN_GYRO_CROSSOVER_HZ` and held still in the rest phases (:func:`twin_attitude`). Twin
``i`` of a recording draws its device, its magnetic environment and its handling offset from
:func:`twin_seed` of ``i`` and the recording's file name, so that the twins of different recordings
draw independently (with seed ``i`` alone, twin ``i`` of every recording had the same noise at the
same time from power-up, and pooling their rests pooled one draw). Recordings of one run that share a
file name (``a/log.mcap``, ``b/log.mcap``) are told apart by their position among them: the first
draws as its name alone says, the next ones from seeds of their own.

Times. The recorded scenario's time 0 is the recording's first valid truth sample, at stamp ``t0``
(``scenario.spec.motion().t0``) in the recording's clock. A twin sample taken at true instant ``t``
corresponds to the real time ``t + t0``.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .recording import Recording
from .site import site_with_seed

if TYPE_CHECKING:
    from gyroemu.dynamics.scenarios import Scenario

__all__ = ["TWIN_SMOOTHING", "TWIN_GYRO_CROSSOVER_HZ", "twin_attitude", "twin_seed", "twin_scenario"]

TWIN_SMOOTHING = {"orientation_cutoff_hz": 20.0, "position_cutoff_hz": 10.0}
"""The twins' smoothing of the recorded motion, one setting for every trial. The attitude the twins
sense is the reference refined by the recording's own gyro above :data:`TWIN_GYRO_CROSSOVER_HZ`
(:func:`twin_attitude`), whose noise is far below the reference's, so its cut-off can sit at 20 Hz:
the real gyro sees the motion's 5–15 Hz content (on trial 02, 20.7 °/s RMS in movement). The
position's is 10 Hz: an optical reference resampled to the IMU's rate has noise that is not white at
that rate, so GCV leaves it almost unsmoothed (143 Hz on BROAD's trial 07) and the twins' accelerometer
would sense the noise as motion (0.5–9 m/s²); the real accelerometer's movement power reaches 7–20 Hz
(99 %), and at 3 Hz the twins lose the linear acceleration that the accelerometer-led filters suffer.
README, "The twin", lists the settings tried."""
TWIN_GYRO_CROSSOVER_HZ = 1.0
"""Below it the twins' attitude follows the optical reference, above it the recording's gyro
(:func:`gyroemu.dynamics.attitude_fusion.complementary_attitude`); the figures sit on a plateau from
0.5 to 2 Hz (README, "The twin")."""


def twin_seed(seed: int, recording: str, same_name_index: int = 0) -> int:
    """The seed of twin ``seed`` of the recording whose file is named ``recording``: the first word of
    ``SeedSequence([seed, crc32(recording)])``, the device's, the magnetic environment's and the handling
    offset's seed (each draws from its own streams of it). ``same_name_index``: how many recordings of
    the run with the same file name come before it; from 1 it joins the sequence's entropy
    (``[seed, crc32(recording), same_name_index]``), so that same-named recordings draw apart while a
    recording whose name is its own keeps its seeds."""
    entropy = [seed, zlib.crc32(recording.encode())]
    if same_name_index:
        entropy.append(same_name_index)
    return int(np.random.SeedSequence(entropy).generate_state(1, np.uint64)[0])


def twin_attitude(
    real_t: np.ndarray,
    q_ref: np.ndarray,
    gyro: np.ndarray,
    rests: Sequence[tuple[float, float]],
    delay_s: float,
    q_bs: Sequence[float] | np.ndarray,
    crossover_hz: float = TWIN_GYRO_CROSSOVER_HZ,
) -> np.ndarray:
    """The attitude the twins of a recording sense, (N, 4) at the recording's samples (NaN before its
    reference starts): the reference ``q_ref`` below ``crossover_hz`` and the recording's own ``gyro``
    (sensor axes, rad/s, lagging the reference by ``delay_s``: the device's latency plus half a sample,
    what its interval means add; turned into body axes by the mounting ``q_bs``) above it, each where it
    is the better measurement (:func:`gyroemu.dynamics.attitude_fusion.complementary_attitude`). In the
    ``rests`` (``(start, stop)`` stretches of ``real_t``) the body is still: held at the stretch's mean, so
    that neither the reference's noise nor the gyro's is sensed as motion there."""
    from gyroemu.dynamics.attitude_fusion import complementary_attitude
    from gyroemu.dynamics.rotation import quat_normalize, quat_rotate

    t = np.asarray(real_t, float)
    gyro = np.asarray(gyro, float)
    read = np.isfinite(gyro).all(axis=1)  # a missing gyro sample is bridged, not integrated as NaN
    omega_s = np.stack([np.interp(t + delay_s, t[read], gyro[read, c]) for c in range(3)], axis=1)
    q = complementary_attitude(t, q_ref, quat_rotate(np.asarray(q_bs, float), omega_s), crossover_hz)
    valid = np.isfinite(np.asarray(q_ref, float)).all(axis=1)
    q[~valid] = np.nan  # where the recording has no reference, neither has its motion
    for start, stop in rests:
        inside = (t >= start) & (t <= stop) & valid
        if inside.any():
            held = q[inside] * np.sign(q[inside] @ q[inside][0])[:, None]  # one hemisphere
            q[inside] = quat_normalize(held.mean(axis=0))
    return q


def twin_scenario(
    real: Recording, site: dict[str, Any], seed: int, smoothing: dict[str, Any] | None = None
) -> Scenario:
    """The ``recorded`` scenario of twin seed ``seed`` (:func:`twin_seed`) of ``real`` in ``site``, with the
    ``[smoothing]`` table ``smoothing`` (the kind's defaults when None)."""
    from gyroemu.dynamics.scenarios import scenario_from_dict

    data = {"kind": "recorded", "path": str(real.path), "format": real.format, "site": site_with_seed(site, seed)}
    if smoothing:
        data["smoothing"] = dict(smoothing)
    return scenario_from_dict(data, name=real.name)

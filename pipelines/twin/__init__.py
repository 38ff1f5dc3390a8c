"""The twin: a recording with truth beside its emulated twins, through the attitude filters
(``gyroemu twin``, :mod:`gyroemu.pipelines.jobs.twin`).

One module per idea: :mod:`.recording` (the real recording and its rest phases), :mod:`.site` (the
twins' site and handling offset), :mod:`.motion` (a twin's motion, its refined attitude and its seed),
:mod:`.runs` (one run, real or twin, through every filter), :mod:`.residuals` (the sensors' residuals
at rest) and :mod:`.report` (the comparison, written as Markdown, JSON and plots).
"""

from .motion import TWIN_GYRO_CROSSOVER_HZ, TWIN_SMOOTHING, twin_attitude, twin_scenario, twin_seed
from .recording import RECORDING_FORMATS, Recording, RecordingError, load_recording, longest_run, rest_phases
from .report import RANKED_FILTERS, TrialResult, TwinReport, format_vector, trial_result
from .residuals import (
    TAUS_S,
    pool_adev,
    pooled_residuals,
    residual_allan,
    rest_residuals,
    rms_over_seeds,
    welch_spectrum,
)
from .runs import GRAVITY_M_S2, METRICS, filter_errors, run_one_twin, run_real
from .site import HANDLING_STREAM, Handling, SiteFileError, read_site, site_with_seed

__all__ = [
    "GRAVITY_M_S2",
    "HANDLING_STREAM",
    "METRICS",
    "RANKED_FILTERS",
    "RECORDING_FORMATS",
    "TAUS_S",
    "TWIN_GYRO_CROSSOVER_HZ",
    "TWIN_SMOOTHING",
    "Handling",
    "Recording",
    "RecordingError",
    "SiteFileError",
    "TrialResult",
    "TwinReport",
    "filter_errors",
    "format_vector",
    "load_recording",
    "longest_run",
    "pool_adev",
    "pooled_residuals",
    "read_site",
    "residual_allan",
    "rest_phases",
    "rest_residuals",
    "rms_over_seeds",
    "run_one_twin",
    "run_real",
    "site_with_seed",
    "trial_result",
    "twin_attitude",
    "twin_scenario",
    "twin_seed",
    "welch_spectrum",
]

"""Issue #17, item 3: the MEKF's attitude covariance tells the truth (slow tier).

On simulated runs with exact truth (the smooth random manoeuvre and the car drive, consumer and tactical
MEMS; 20 runs of 30 s each), the normalised estimation error squared eᵀ P⁻¹ e of the attitude, averaged
over the runs at 20 instants after 15 s, lies inside the two-sided 95 % band of χ²(dof·N)/N at 16 or
more of the 20 instants (dof 3 in 9D, 2 in 6D, whose heading is not observed), for the online filter
and for the smoother. Run k flies the random manoeuvre of seed 1000 + k with the device of seed k (the
band needs N independent draws of everything the filter models as random; the car drive has no random
part). The protocol is ``tests/nees_protocol.py``, which ``python tests/benchmarks/nees_check.py`` also
runs (with the forward pass's figures).

Held here for the consumer MEMS, whose two cases are inside their band on seeds 0–19 and on the
seeds 20–59 that no parameter was chosen on. The tactical MEMS is not held: its cases pass or fail by
the seed set (the smooth manoeuvre's per-run NEES is heavy-tailed: mean 1.91, median 0.79 over 60 runs;
the car's smoothed pass 10, 13 and 9 of 20 instants), which README reports as missed. The car drive
is held twice: the scenario's one drive, shared by the runs (so its mean NEES is partly one draw of
that drive's error), and 20 drives drawn per run from their seeds (``tests/car_drives.py``: legs,
acceleration, first turn and bump; heading north as the scenario's), whose runs are independent draws
as the band assumes. Drawn with its heading too (``nees_check.py --drawn-car all``) the consumer's
heading leaves its band while its tilt stays inside (README): not held.
"""

from __future__ import annotations

import numpy as np
import pytest
from nees_protocol import nees_runs
from scipy.stats import chi2

RUNS, DURATION, SKIP, POINTS = 20, 30.0, 15.0, 20


@pytest.mark.slow
@pytest.mark.parametrize(
    ("scenario", "drawn"), [("smooth_manoeuvre", False), ("car_drive", False), ("car_drive", True)]
)
def test_attitude_nees_lies_in_its_chi2_band(scenario, drawn):
    """The issue's bar: the mean NEES over the runs inside its 95 % χ² band at 16 or more of 20 instants
    (the instants are correlated in time, so no tighter count follows from the band alone)."""
    drawn_car = "course" if drawn else None
    nees, dof = nees_runs(scenario, "consumer_mems", RUNS, DURATION, SKIP, POINTS, drawn_car=drawn_car)
    lo, hi = chi2.ppf([0.025, 0.975], dof * RUNS) / RUNS
    for key in ("online", "smoothed"):
        mean = nees[key].mean(axis=0)
        inside = int(np.sum((mean > lo) & (mean < hi)))
        assert inside >= 16, f"{key}: mean NEES {np.round(mean, 2).tolist()} against [{lo:.2f}, {hi:.2f}]"

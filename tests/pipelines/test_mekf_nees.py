"""Issue #17, item 3: the MEKF's attitude covariance tells the truth (slow tier).

On simulated runs with exact truth (the smooth random manoeuvre and the car drive, consumer and tactical
MEMS; 20 runs of 30 s each), the normalised estimation error squared eᵀ P⁻¹ e of the attitude, averaged
over the runs at 20 instants after 15 s, lies inside the two-sided 95 % band of χ²(dof·N)/N at 16 or
more of the 20 instants (dof 3 in 9D, 2 in 6D, whose heading is not observed), for the online filter
and for the smoother. Run k flies the random manoeuvre of seed 1000 + k with the device of seed k (the
band needs N independent draws of everything the filter models as random; the car drive has no random
part). The same protocol and the forward pass's figures: ``python tests/benchmarks/nees_check.py``.

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

import tomllib
from pathlib import Path

import numpy as np
import pytest
from car_drives import drawn_car_drive
from scipy.stats import chi2

from gyroemu.dynamics import load_scenario, scenario_from_dict
from gyroemu.pipelines.estimation.mekf import MekfParams
from gyroemu.pipelines.estimation.mekf_smoother import smooth_log, smoother_params
from gyroemu.pipelines.estimation.metrics import attitude_nees
from gyroemu.pipelines.estimation.setup import setup_for
from gyroemu.sensors import load_device
from gyroemu.sensors.sampling import SensorTruth

SCENARIOS = Path(__file__).resolve().parents[2] / "configs" / "scenarios"
RUNS, DURATION, SKIP, POINTS = 20, 30.0, 15.0, 20


def _nees(scenario: str, device: str, drawn: bool = False) -> tuple[dict[str, np.ndarray], int]:
    """Per pass ('online', 'smoothed'): the attitude NEES (RUNS, POINTS); and its degrees of freedom. With
    ``drawn`` each run's car drive is drawn from its seed (heading kept)."""
    data = tomllib.loads((SCENARIOS / f"{scenario}.toml").read_text())
    random = data.get("kind") == "random-manoeuvre" or drawn
    shared = None if random else load_scenario(scenario)
    shared_traj = None if shared is None else shared.simulate(duration=DURATION)
    out: dict[str, list[np.ndarray]] = {"online": [], "smoothed": []}
    dof = 3
    for run in range(RUNS):
        if drawn:
            scen = scenario_from_dict(drawn_car_drive(data, 1000 + run, heading=False))
        else:
            scen = scenario_from_dict(data | {"seed": 1000 + run}) if random else shared
        traj = scen.simulate(duration=DURATION) if random else shared_traj
        dev = load_device(device, seed=run)
        samples = dev.measure(traj)
        q_true = SensorTruth(traj).body_truth(samples.t_true if samples.t_true is not None else samples.t)[0]
        setup = setup_for(dev, scen)
        mag = samples.mag if setup.use_mag else None
        t = np.asarray(samples.t, float) - samples.t[0]
        online = smooth_log(setup, t, samples.gyro, samples.accel, mag, params=MekfParams.for_setup(setup)).forward
        smoothed = smooth_log(setup, t, samples.gyro, samples.accel, mag, params=smoother_params(setup)).smoothed
        idx = np.linspace(np.searchsorted(t, SKIP), len(t) - 1, POINTS).astype(int)
        dof = 3 if setup.use_mag else 2
        for key, est in (("online", online), ("smoothed", smoothed)):
            out[key].append(attitude_nees(q_true[idx], est.q_wb[idx], est.q_wb_covariance[idx], dof))
    return {k: np.array(v) for k, v in out.items()}, dof


@pytest.mark.slow
@pytest.mark.parametrize(
    ("scenario", "drawn"), [("smooth_manoeuvre", False), ("car_drive", False), ("car_drive", True)]
)
def test_attitude_nees_lies_in_its_chi2_band(scenario, drawn):
    """The issue's bar: the mean NEES over the runs inside its 95 % χ² band at 16 or more of 20 instants
    (the instants are correlated in time, so no tighter count follows from the band alone)."""
    nees, dof = _nees(scenario, "consumer_mems", drawn)
    lo, hi = chi2.ppf([0.025, 0.975], dof * RUNS) / RUNS
    for key, values in nees.items():
        mean = values.mean(axis=0)
        inside = int(np.sum((mean > lo) & (mean < hi)))
        assert inside >= 16, f"{key}: mean NEES {np.round(mean, 2).tolist()} against [{lo:.2f}, {hi:.2f}]"

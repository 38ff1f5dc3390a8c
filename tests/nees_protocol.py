"""The NEES protocol of issue #17, item 3, shared by ``tests/pipelines/test_mekf_nees.py`` (what it holds)
and ``tests/benchmarks/nees_check.py`` (what README reports): N runs with exact truth, each its own
device seed and, where the scenario has one, its own random part; the attitude NEES of the online
filter, the smoother's forward pass and the smoother at fixed instants."""

import tomllib
from pathlib import Path

import numpy as np
from car_drives import drawn_car_drive

from gyroemu.dynamics import load_scenario, scenario_from_dict
from gyroemu.pipelines.estimation.mekf import MekfParams
from gyroemu.pipelines.estimation.mekf_smoother import smooth_log, smoother_params
from gyroemu.pipelines.estimation.metrics import attitude_error_vector, attitude_nees
from gyroemu.pipelines.estimation.setup import setup_for
from gyroemu.sensors import load_device
from gyroemu.sensors.sampling import SensorTruth

SCENARIOS = Path(__file__).resolve().parents[1] / "configs" / "scenarios"


def scenario_run(scenario: str, run: int, fixed: bool, drawn_car: str | None = None):
    """The scenario of run ``run``: a random manoeuvre with its own seed (1000 + run) unless ``fixed``; with
    ``drawn_car`` (``"all"`` or ``"course"``: all but the initial heading) a car drive drawn from 1000 + run."""
    data = tomllib.loads((SCENARIOS / f"{scenario}.toml").read_text())
    if data.get("kind") == "car" and drawn_car is not None:
        return scenario_from_dict(drawn_car_drive(data, 1000 + run, heading=drawn_car == "all"))
    if data.get("kind") != "random-manoeuvre" or fixed:
        return load_scenario(scenario)
    return scenario_from_dict(data | {"seed": 1000 + run})


def nees_runs(
    scenario: str,
    device: str,
    seeds: int,
    duration: float,
    skip_s: float,
    points: int,
    fixed=False,
    online: dict[str, float] | None = None,
    smooth: dict[str, float] | None = None,
    first_seed: int = 0,
    errors: dict[str, list[tuple[np.ndarray, np.ndarray]]] | None = None,
    drawn_car: str | None = None,
):
    """Per estimator ('online', 'forward', 'smoothed'): the attitude NEES (seeds, points), and the degrees of
    freedom. ``online`` and ``smooth`` override the online filter's and the smoother's parameters.
    ``errors``, when given, receives per estimator each run's attitude error (points, dof), rad, world
    axes, and covariance (points, dof, dof)."""
    out: dict[str, list[np.ndarray]] = {"online": [], "forward": [], "smoothed": []}
    dof = 3
    trajectories: dict[str, tuple] = {}
    for seed in range(first_seed, first_seed + seeds):
        scen = scenario_run(scenario, seed, fixed, drawn_car)
        key = scen.spec.model_dump_json() if hasattr(scen.spec, "model_dump_json") else repr(scen.spec)
        if key not in trajectories:  # a scenario without a random part is simulated once
            trajectories = {key: (scen, scen.simulate(duration=duration))}
        scen, traj = trajectories[key]
        dev = load_device(device, seed=seed)
        samples = dev.measure(traj)
        q_true = SensorTruth(traj).body_truth(samples.t_true if samples.t_true is not None else samples.t)[0]
        setup = setup_for(dev, scen)
        mag = samples.mag if setup.use_mag else None
        t = np.asarray(samples.t, float) - samples.t[0]
        res = smooth_log(setup, t, samples.gyro, samples.accel, mag, params=smoother_params(setup, **(smooth or {})))
        on = smooth_log(
            setup, t, samples.gyro, samples.accel, mag, params=MekfParams.for_setup(setup, **(online or {}))
        ).forward
        idx = np.linspace(np.searchsorted(t, skip_s), len(t) - 1, points).astype(int)
        dof = 3 if setup.use_mag else 2
        for key, est in (("online", on), ("forward", res.forward), ("smoothed", res.smoothed)):
            out[key].append(attitude_nees(q_true[idx], est.q_wb[idx], est.q_wb_covariance[idx], dof))
            if errors is not None:
                e = attitude_error_vector(q_true[idx], est.q_wb[idx])[:, :dof]
                errors.setdefault(key, []).append((e, est.q_wb_covariance[idx, :dof, :dof]))
    return {k: np.array(v) for k, v in out.items()}, dof

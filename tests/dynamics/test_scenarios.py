"""Every built-in scenario loads, simulates, and round-trips through its resolved TOML."""

import tomllib

import numpy as np
import pytest

from gyroemu.dynamics import KINDS, ConfigError, Trajectory, list_scenarios, load_scenario, scenario_from_dict
from gyroemu.dynamics.config import config_dir

BUILTIN = sorted(p.stem for p in (config_dir() / "scenarios").glob("*.toml"))


def test_every_kind_has_a_builtin_scenario():
    kinds = {s.kind for s in list_scenarios()}
    assert kinds == set(KINDS)


@pytest.mark.parametrize("name", BUILTIN)
def test_builtin_scenario_simulates_a_short_span(name):
    scenario = load_scenario(name)
    assert scenario.description, "the one-line description is what 'gyroemu scenarios' prints"
    duration = min(scenario.duration_s, 2.0)
    traj = scenario.simulate(duration=duration)
    assert isinstance(traj, Trajectory)
    n = int(round(duration * scenario.rate_hz)) + 1
    assert len(traj) == n
    np.testing.assert_allclose(np.diff(traj.t), 1 / scenario.rate_hz, rtol=1e-9)
    for name_, value in vars(traj).items():
        if isinstance(value, np.ndarray):
            assert np.all(np.isfinite(value)), name_
    np.testing.assert_allclose(np.linalg.norm(traj.q_wb, axis=1), 1.0, atol=1e-12)
    # The fully resolved TOML reloads to the same spec.
    again = scenario_from_dict(tomllib.loads(scenario.to_toml()))
    assert again.spec == scenario.spec


def test_unknown_and_missing_kind_are_named():
    with pytest.raises(ConfigError, match="key 'kind': unknown kind 'spinning-plate'"):
        scenario_from_dict({"kind": "spinning-plate", "duration_s": 1, "rate_hz": 1}, name="x.toml")
    with pytest.raises(ConfigError, match="key 'kind': missing required key"):
        scenario_from_dict({"duration_s": 1, "rate_hz": 1}, name="x.toml")

"""gyroemu's truth simulator: rigid bodies, prescribed motions and the Earth, sampled as a Trajectory.

Entry points (``interface.md``): :func:`load_scenario` and :meth:`Scenario.simulate`, returning a
:class:`Trajectory`. Rotation helpers live in :mod:`gyroemu.dynamics.rotation`, inertia tensors in
:mod:`gyroemu.dynamics.inertia`.
"""

from __future__ import annotations

from .config import ConfigError
from .earth import EARTH_RATE, Environment, Site, earth_rate_enu, normal_gravity
from .scenarios import KINDS, Scenario, ScenarioSpec, list_scenarios, load_scenario, scenario_from_dict
from .trajectory import Trajectory, trajectory_from_world_motion

__all__ = [
    "ConfigError",
    "EARTH_RATE",
    "Environment",
    "Site",
    "earth_rate_enu",
    "normal_gravity",
    "KINDS",
    "Scenario",
    "ScenarioSpec",
    "list_scenarios",
    "load_scenario",
    "scenario_from_dict",
    "Trajectory",
    "trajectory_from_world_motion",
]

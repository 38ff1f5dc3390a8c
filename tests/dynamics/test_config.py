"""Config validation: every problem becomes a ConfigError naming the file and the key."""

from typing import Literal

import pytest

from gyroemu.dynamics.config import ConfigError, PositiveReal, Section, Vec3, read_toml, resolve_config, validate


class Body(Section):
    mass_kg: PositiveReal
    inertia_kgm2: Vec3


class Spec(Section):
    kind: Literal["x"]
    duration_s: PositiveReal
    body: Body


GOOD = {"kind": "x", "duration_s": 2, "body": {"mass_kg": 1, "inertia_kgm2": [1, 2, 2.5]}}


def with_(path, value):
    data = {**GOOD, "body": dict(GOOD["body"])}
    *parents, last = path.split(".")
    target = data
    for p in parents:
        target = target[p]
    if value is None:
        del target[last]
    else:
        target[last] = value
    return data


def test_good_config_is_typed_and_frozen():
    spec = validate(Spec, GOOD, file="a.toml")
    assert spec.duration_s == 2.0 and isinstance(spec.duration_s, float)
    assert spec.body.inertia_kgm2 == (1.0, 2.0, 2.5)
    with pytest.raises(Exception):
        spec.duration_s = 3.0


@pytest.mark.parametrize(
    "data, key, words",
    [
        (with_("duration_s", None), "duration_s", "missing required key"),
        (with_("body.mass_kg", -1.0), "body.mass_kg", "greater than 0"),
        (with_("duration_s", "10 s"), "duration_s", "expected a number"),
        (with_("duration_s", True), "duration_s", "expected a number"),
        (with_("body.inertia_kgm2", [1, 2, "a"]), "body.inertia_kgm2[2]", "expected a number"),
        ({**with_("duration_s", None), "duration_ms": 2}, "duration_ms", "did you mean 'duration_s'"),
        (with_("body.inertia", 3), "body.inertia", "did you mean 'inertia_kgm2'"),
    ],
)
def test_errors_name_file_and_key(data, key, words):
    with pytest.raises(ConfigError) as info:
        validate(Spec, data, file="scenario.toml")
    assert info.value.file == "scenario.toml"
    assert info.value.key == key
    assert words in str(info.value)
    assert str(info.value).startswith(f"scenario.toml: key '{key}': ")


def test_read_toml_errors_name_the_file(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        read_toml(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("kind = \n")
    with pytest.raises(ConfigError, match="bad.toml: not valid TOML"):
        read_toml(bad)


def test_unknown_builtin_name_lists_the_known_ones():
    with pytest.raises(ConfigError, match="unknown scenario 'no_such_thing'.*built-in scenarios"):
        resolve_config("no_such_thing", "scenarios", "scenario")

"""Config files: TOML read at the edge and validated into typed, frozen objects.

Every config problem surfaces as one exception type, :class:`ConfigError`, whose message names the
file and the dotted key at fault (``body.inertia_kgm2``). Keys carry their unit in their name
(``duration_s``, ``arw_deg_per_sqrt_h``), so a key with the wrong unit is an unknown key, and the
error suggests the known key it most resembles.

Sections are pydantic models (``extra="forbid"``, frozen). Numbers are given as :data:`Real`, which
refuses strings and booleans (TOML's ``"10 s"`` or ``true`` where a number belongs) instead of
coercing them.
"""

from __future__ import annotations

import difflib
import importlib.resources
import math
import os
import re
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, TypeVar

import pydantic
from pydantic import BaseModel, ConfigDict, Field

from gyroemu.errors import ConfigError

__all__ = [
    "ConfigError",
    "Section",
    "Real",
    "as_number",
    "at_most",
    "at_least",
    "MAX_ANGLE_TURNS",
    "AngleRad",
    "AngleDeg",
    "AnglesDeg",
    "PositiveReal",
    "NonNegativeReal",
    "Vec3",
    "Quat",
    "read_toml",
    "validate",
    "config_dir",
    "resolve_config",
]


def as_number(value: Any) -> float:
    """``value`` as a finite float; strings, booleans and non-finite numbers raise ``ValueError``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"expected a number, got {type(value).__name__} {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"expected a finite number, got {value}")
    return float(value)


def at_most(limit: float, reason: str) -> pydantic.AfterValidator:
    """A pydantic validator refusing a number above ``limit`` with ``reason`` (why the bound: the size
    it would make, what it would cost), for keys that size a run (counts of terms, spans, rates)."""

    def check(value: float) -> float:
        if value > limit:
            raise ValueError(f"{value:g} is more than the limit of {limit:g}: {reason}")
        return value

    return pydantic.AfterValidator(check)


def at_least(limit: float, reason: str) -> pydantic.AfterValidator:
    """A pydantic validator refusing a number below ``limit`` with ``reason`` (why the bound), the
    counterpart of :func:`at_most` for keys whose small values blow up what they divide."""

    def check(value: float) -> float:
        if value < limit:
            raise ValueError(f"{value:g} is less than the limit of {limit:g}: {reason}")
        return value

    return pydantic.AfterValidator(check)


MAX_ANGLE_TURNS = 4
"""The largest magnitude of an orientation angle given in radians (``AngleRad``), in turns (4 turns,
8π = 25.1 rad, 1440°). An orientation angle means the same modulo a turn, so a config writes it within
a turn or two (−π…π, 0…2π, or a spin phase a little past it); a value far beyond is a unit slip
(degrees in a ``_rad`` key: 90 there is 14 turns), and at 10³⁰⁰ rad no digit of its sine or cosine is
left (float64 spaces numbers above 2⁵² · 2π ≈ 2.8·10¹⁶ more than a turn apart)."""


def _within_turns(turn: float, unit: str, slip: str) -> pydantic.AfterValidator:
    """A validator refusing an orientation angle beyond :data:`MAX_ANGLE_TURNS` turns of ``turn`` (in
    ``unit``), saying which unit slip such a value most likely is (``slip``)."""

    def check(value: float) -> float:
        if abs(value) > MAX_ANGLE_TURNS * turn:
            raise ValueError(
                f"{value:g}{unit} is more than {MAX_ANGLE_TURNS} turns (±{MAX_ANGLE_TURNS * turn:.4g}{unit}): an "
                f"orientation angle means the same modulo {turn:.4g}{unit} ({slip})"
            )
        return value

    return pydantic.AfterValidator(check)


Real = Annotated[float, pydantic.BeforeValidator(as_number)]
PositiveReal = Annotated[Real, Field(gt=0)]
NonNegativeReal = Annotated[Real, Field(ge=0)]
Vec3 = tuple[Real, Real, Real]
AngleRad = Annotated[Real, _within_turns(2 * math.pi, " rad", "degrees given in radians?")]
"""An orientation angle in radians, at most :data:`MAX_ANGLE_TURNS` turns either way."""
AngleDeg = Annotated[Real, _within_turns(360.0, "°", "radians given in degrees would be small: a unit slip?")]
"""An orientation angle in degrees, at most :data:`MAX_ANGLE_TURNS` turns either way."""
AnglesDeg = tuple[AngleDeg, AngleDeg, AngleDeg]
"""Three orientation angles in degrees (roll, pitch, yaw), each :data:`AngleDeg`."""
Quat = tuple[Real, Real, Real, Real]


class Section(BaseModel):
    """Base of every config table: unknown keys are refused, values are immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True, arbitrary_types_allowed=True)


M = TypeVar("M", bound=BaseModel)


def read_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file into a dict, or raise :class:`ConfigError` naming the file."""
    path = Path(path)
    try:
        with path.open("rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError("no such file", file=path) from None
    except IsADirectoryError:
        raise ConfigError("is a directory, not a TOML file", file=path) from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"not valid TOML: {e}", file=path) from None
    except UnicodeDecodeError:
        raise ConfigError("not valid TOML: not UTF-8 text", file=path) from None


def validate(model: type[M], data: Any, *, file: str | Path | None = None, prefix: str = "") -> M:
    """Validate ``data`` (a dict from TOML) into ``model``, or raise :class:`ConfigError`.

    The error names ``file`` and the first offending key (dotted, below ``prefix``); the reason lists
    every problem pydantic found, one per line.
    """
    try:
        return model.model_validate(data)
    except pydantic.ValidationError as e:
        errors = e.errors(include_url=False)
        # A misspelt or wrongly-unitted key usually also leaves a required key missing: name it first.
        errors.sort(key=lambda err: err["type"] != "extra_forbidden")
        problems = [_describe(model, err) for err in errors]
        key = ".".join(p for p in (prefix, problems[0][0]) if p) or None
        lines = [problems[0][1]] + [
            f"also key '{'.'.join(p for p in (prefix, k) if p)}': {why}" for k, why in problems[1:]
        ]
        raise ConfigError("\n  ".join(lines), file=file, key=key) from None


def _describe(model: type[BaseModel], err: Mapping[str, Any]) -> tuple[str, str]:
    loc = [p for p in err["loc"] if not str(p).startswith("function-")]
    key = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in loc).lstrip(".")
    loc = [str(p) for p in loc]
    kind = err["type"]
    if kind == "extra_forbidden":
        known = _fields_at(model, loc[:-1])
        hint = difflib.get_close_matches(loc[-1], known, n=1, cutoff=0.5)
        why = "unknown key"
        if hint:
            why += f" (did you mean '{hint[0]}'? key names carry their unit)"
        elif known:
            why += f" (known keys: {', '.join(sorted(known))})"
        return key, why
    if kind == "missing":
        return key, "missing required key"
    msg = err["msg"]
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, ") :]
    named = _NAMED_KEY.match(msg) if not key else None
    if named:  # a check of the whole section that names the key it faults: "initial.height_m: ..."
        return named.group(1), msg[named.end() :]
    return key, msg


_NAMED_KEY = re.compile(r"^([a-z][a-z0-9_]*(?:\.[a-z][a-z0-9_]*)*): ")


def _fields_at(model: type[BaseModel], loc: list[str]) -> list[str]:
    """Field names of the (nested) section at ``loc``; empty where it cannot be followed."""
    current: Any = model
    for part in loc:
        fields = getattr(current, "model_fields", None)
        if not fields or part not in fields:
            return []
        current = fields[part].annotation
        # Optional[Section] and similar unions: take the first model among the arguments.
        for arg in getattr(current, "__args__", ()) or ():
            if isinstance(arg, type) and issubclass(arg, BaseModel):
                current = arg
                break
    fields = getattr(current, "model_fields", None)
    return list(fields) if fields else []


def config_dir() -> Path:
    """The folder of built-in scenarios and devices (``$GYROEMU_CONFIG_DIR`` overrides).

    The package :mod:`gyroemu.configs`, found with :mod:`importlib.resources`, so the same code serves a
    wheel, an editable install and a source checkout. gyroemu installs as plain files (numba caches its
    machine code beside them), so the resource is a directory on disk.
    """
    override = os.environ.get("GYROEMU_CONFIG_DIR")
    if override:
        return Path(override)
    root = importlib.resources.files("gyroemu.configs")
    if not isinstance(root, Path):  # pragma: no cover - a zipped install, which gyroemu does not support
        raise RuntimeError(f"gyroemu's built-in configs are not a folder on disk: {root}")
    return root


def resolve_config(name_or_path: str | Path, folder: str, what: str) -> Path:
    """The file a built-in name (``configs/<folder>/<name>.toml``) or a path refers to.

    Raises :class:`ConfigError` naming the argument and the built-in names when neither exists.
    """
    text = str(name_or_path)
    path = Path(text)
    if text.endswith(".toml") or path.exists() or "/" in text:
        if path.is_dir():
            raise ConfigError(f"is a folder, not a {what} file: name a .toml file in it", file=path)
        if not path.is_file():
            raise ConfigError("no such file", file=path)
        return path
    builtin = config_dir() / folder / f"{text}.toml"
    if builtin.is_file():
        return builtin
    names = sorted(p.stem for p in (config_dir() / folder).glob("*.toml"))
    hint = difflib.get_close_matches(text, names, n=1)
    raise ConfigError(
        f"unknown {what} '{text}'"
        + (f" (did you mean '{hint[0]}'?)" if hint else "")
        + f"; built-in {what}s: {', '.join(names) or 'none'}; or give a path to a .toml file"
    )

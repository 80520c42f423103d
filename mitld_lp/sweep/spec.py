"""Sweep files: a base model file, fixed changes, and the parameters to vary.

The schema (also in docs/sweeps.md)::

    name = "bus_sweep"                  # required, non-empty string
    model = "bus_grid.toml"             # required: the base model file, relative to this file

    [set]                               # optional: changes made to the base model for
    constants.T = 3                     # every point (tables merge key by key)

    [vary]                              # optional: every combination of these values
    constants.T = [1, 2, 3]             # (a grid; the last key varies fastest)
    distributions.mu2.geometric = [0.2, 0.3]

    [points]                            # optional: a list of points, the i-th taking the
    grid.slip = [0.0, 0.1]              # i-th value of every list (all of one length)
    epsilon = [0.01, 0.05]

    [solve]                             # optional: how each point is solved
    method = "lp"                       # "lp" or "vi"
    solver = "CLARABEL"                 # an LP solver cvxpy has
    backend = "auto"                    # "auto", "direct" or "cvxpy"
    clock_reduction = true
    decompose = true
    time_limit = 60                     # seconds of each point's solve stage
    max_states = 5000000                # each point's product budget (states)
    max_memory = 4000000000             # and memory (bytes; default half the machine's)
    precision = 1e-6                    # the certified bracket's relative width
    bands = "worst"                     # a band's law worst for the robot, or "best"

A parameter is any key path of the model file: TOML's dotted keys are the key path.
Under ``[vary]`` and ``[points]`` the values of a parameter are a list (so varying a
whole law, ``distributions.mu = [{ poisson = 2 }, { geometric = 0.3 }]``, replaces the
table).  The tables of a varied key path must exist in the base model after ``[set]``;
its last key may be absent when the model file knows it (``epsilon``, ``grid.slip``
have defaults).  With both
``[points]`` and ``[vary]``, every point of the list is combined with every combination
of the grid; with neither, the sweep is the one model.

A sweep is identified (``Sweep.sweep_id``) by its name, the base model file's text,
``[set]``, the names of the parameters and the ``[solve]`` settings that change an
answer (not ``time_limit`` nor ``max_states``), not by the values: a sweep extended by
more values keeps its identity, so that the points already computed are reused.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import os
import re
import tomllib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import date, datetime, time
from pathlib import Path
from typing import Any

from mitld_lp import defaults
from mitld_lp.files import rules as file_rules
from mitld_lp.files.keys import KeyContext
from mitld_lp.model import ModelError, loads_model
from mitld_lp.problem import ProblemError, Settings
from mitld_lp.sweep.rows import RESERVED_COLUMNS
from mitld_lp.util.text import printable

__all__ = [
    "Sweep",
    "SweepError",
    "load_sweep",
    "key_path_text",
    "to_toml",
    "MAX_POINTS",
]

MAX_POINTS = 100_000
"""Largest number of points a sweep may have (checked before any point is made)."""



class SweepError(ValueError):
    """A sweep file or results file is invalid: ``SOURCE: KEY.PATH: what is wrong``."""

    def __init__(self, message: str) -> None:
        super().__init__(printable(message))


KeyPath = tuple[str, ...]


def _part(part: str) -> str:
    return part if re.fullmatch(r"[A-Za-z0-9_-]+", part) else json.dumps(part,
                                                                          ensure_ascii=False)


def key_path_text(path: Sequence[str]) -> str:
    """A key path as TOML writes it: ``grid.slip``, ``regions."a b"``."""
    return ".".join(_part(p) for p in path)


# --------------------------------------------------------------------------- TOML text


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        return repr(value) if math.isfinite(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        if not value:
            return "{}"
        return "{ " + ", ".join(f"{_part(k)} = {_toml_value(v)}" for k, v in value.items()) + " }"
    if isinstance(value, datetime | date | time):
        return value.isoformat()
    raise TypeError(f"no TOML text for {type(value).__name__} {value!r}")


def to_toml(doc: Mapping[str, Any]) -> str:
    """A TOML document that ``tomllib.loads`` reads back as ``doc``: the top-level
    values first, then one ``[table]`` per top-level table (deeper tables inline)."""
    lines = [f"{_part(k)} = {_toml_value(v)}" for k, v in doc.items() if not isinstance(v, dict)]
    for k, v in doc.items():
        if isinstance(v, dict):
            lines += ["", f"[{_part(k)}]"]
            lines += [f"{_part(k2)} = {_toml_value(v2)}" for k2, v2 in v.items()]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- settings


# --------------------------------------------------------------------------- the sweep


@dataclass(frozen=True, slots=True)
class Sweep:
    """A loaded, validated sweep file.

    Attributes:
        name: the sweep's ``name``.
        model_path: the base model file (absolute).
        base: the base model document with ``[set]`` applied (a TOML table).
        parameters: the varied key paths, in the order of the columns.
        points: one tuple of values per point, in the order of ``parameters``.
        settings: how each point is solved.
        sweep_id: 16 hex digits identifying the sweep (module docstring).
        source: the sweep file, for messages.
    """

    name: str
    model_path: Path
    base: Mapping[str, Any] = field(repr=False)
    parameters: tuple[KeyPath, ...]
    points: tuple[tuple[Any, ...], ...] = field(repr=False)
    settings: Settings
    sweep_id: str
    source: str

    @property
    def columns(self) -> tuple[str, ...]:
        """The parameters' column names: their key paths as text."""
        return tuple(key_path_text(p) for p in self.parameters)

    def model_document(self, values: Sequence[Any]) -> dict[str, Any]:
        """The model document of the point with these ``values``."""
        doc = copy.deepcopy(dict(self.base))
        for path, value in zip(self.parameters, values, strict=True):
            table = doc
            for part in path[:-1]:
                table = table[part]
            table[path[-1]] = copy.deepcopy(value)
        return doc

    def model_text(self, values: Sequence[Any]) -> str:
        """The model file of the point with these ``values``, as TOML text."""
        head = ", ".join(f"{c} = {_toml_value(v)}"
                         for c, v in zip(self.columns, values, strict=True))
        comment = f"# sweep {self.name}, point {head or '(the base model)'}\n"
        return printable(comment.rstrip("\n")) + "\n" + to_toml(self.model_document(values))


def _flatten(table: Mapping[str, Any], prefix: KeyPath) -> Iterator[tuple[KeyPath, Any]]:
    """``(key path, value)`` for every non-table value below ``table``."""
    for k, v in table.items():
        if isinstance(v, dict):
            yield from _flatten(v, (*prefix, k))
        else:
            yield (*prefix, k), v


def _lists(table: Mapping[str, Any], prefix: KeyPath) -> Iterator[tuple[KeyPath, Any]]:
    """``(key path, list of values)``: tables recurse, the first non-table is the list."""
    for k, v in table.items():
        if isinstance(v, dict) and v:
            yield from _lists(v, (*prefix, k))
        else:
            yield (*prefix, k), v


def _merge(doc: dict[str, Any], path: KeyPath, value: Any, where: str, ctx: KeyContext) -> None:
    table = doc
    for i, part in enumerate(path[:-1]):
        nxt = table.setdefault(part, {})
        if not isinstance(nxt, dict):
            raise ctx.error(where, f"{key_path_text(path[:i + 1])} is not a table in the "
                            "model, so it has no keys to set")
        table = nxt
    table[path[-1]] = copy.deepcopy(value)


def _setting(table: dict[str, Any], ctx: KeyContext) -> Settings:
    ctx.keys(table, "solve", set(), set(_SOLVE_KEYS))  # epsilon is the model's
    values: dict[str, Any] = {}
    for k, v in table.items():
        where = f"solve.{k}"
        if k in ("clock_reduction", "decompose"):
            if not isinstance(v, bool):
                raise ctx.error(where, f"must be true or false, got {_toml_value(v)}")
        elif k in _RULES:  # the rule every surface applies (mitld_lp.defaults)
            try:
                v = _RULES[k](v, _toml_value(v))
            except ValueError as exc:
                raise ctx.error(where, str(exc)) from None
        else:
            choices = {"method": defaults.METHODS, "backend": defaults.BACKENDS}.get(k)
            if not isinstance(v, str) or (choices and v not in choices):
                allowed_text = " or ".join(f'"{c}"' for c in choices) if choices else "a string"
                raise ctx.error(where, f"must be {allowed_text}, got {_toml_value(v)}")
            if k == "solver":
                v = v.strip().upper()
        values[k] = v
    try:
        return Settings(**values).checked()
    except ProblemError as exc:
        raise ctx.error("solve", str(exc)) from None


#: The checks of a sweep's ``[solve]`` numbers (the library's and the model file's).
_RULES = {"time_limit": defaults.check_seconds, "tol": defaults.check_unit,
          "certify_tol": defaults.check_unit, "precision": defaults.check_unit,
          "bands": defaults.check_bands, "max_states": defaults.check_count,
          "max_automaton_states": defaults.check_count, "max_memory": defaults.check_memory}

#: The keys of a sweep's ``[solve]`` table: the settings a point is solved with.
_SOLVE_KEYS = frozenset({"method", "solver", "backend", "clock_reduction", "decompose",
                         "time_limit", "max_states", "max_automaton_states", "max_memory",
                         "tol", "certify_tol", "precision", "bands"})


def _parameter_lists(doc: dict[str, Any], key: str, ctx: KeyContext) -> list[tuple[KeyPath, list]]:
    table = ctx.table(doc.get(key, {}), key)
    out = []
    for path, values in _lists(table, ()):
        where = f"{key}.{key_path_text(path)}"
        if not isinstance(values, list):
            raise ctx.error(where, f"must be a list of values, got {_toml_value(values)}")
        if not values:
            raise ctx.error(where, "must not be empty")
        out.append((path, values))
    return out


def _check_path(base: Mapping[str, Any], path: KeyPath, first: Any, where: str, model: str,
                model_path: Path, ctx: KeyContext) -> None:
    """Every table on ``path`` must exist in the base model; a key the base does not have
    (one with a default, such as ``epsilon``) must be one the model file knows."""
    table: Any = base
    for i, part in enumerate(path[:-1]):
        if not isinstance(table, dict) or part not in table:
            raise ctx.error(where, f"the model ({model} with [set]) has no "
                            f"{key_path_text(path[:i + 1])}; give it a value under [set] "
                            "first")
        table = table[part]
    if not isinstance(table, dict):
        raise ctx.error(where, f"{key_path_text(path[:-1])} is not a table in the model")
    if path[-1] in table:
        return
    doc = copy.deepcopy(dict(base))
    _merge(doc, path, first, where, ctx)
    try:
        loads_model(to_toml(doc), os.fspath(model_path))
    except ModelError as exc:
        if f": {key_path_text(path)}: unknown key" in str(exc):
            raise ctx.error(where, f"the model file has no key {key_path_text(path)} "
                            + str(exc).split(": unknown key ", 1)[1]) from None


def _count(lists: Sequence[tuple[KeyPath, list]]) -> int:
    return math.prod(len(v) for _, v in lists)


def load_sweep(path: str | os.PathLike[str]) -> Sweep:
    """Load and validate the sweep file at ``path`` (schema in the module docstring).

    The base model with ``[set]`` applied is loaded once, so that a mistake common to
    every point (an unknown key, a bad spec) is reported here.  Raises
    :class:`SweepError` (a :class:`ModelError` of the base model names its file)."""
    source = os.fspath(path)
    ctx = KeyContext(source, error=SweepError)
    try:  # regular files, bounded (file_rules)
        text = file_rules.read_bytes(path).decode("utf-8")
    except file_rules.InputFileError as exc:
        raise SweepError(str(exc)) from exc
    except OSError as exc:
        raise ctx.error("", f"cannot read: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise ctx.error("", f"not UTF-8 text: {exc}") from exc
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ctx.error("", f"TOML syntax error: {exc}") from None
    ctx.keys(doc, "", {"name", "model"}, {"set", "vary", "points", "solve"})
    for k in ("name", "model"):
        if not isinstance(doc[k], str) or not doc[k].strip():
            raise ctx.error(k, f"must be a non-empty string, got {_toml_value(doc[k])}")
    model_path = (Path(source).resolve().parent / doc["model"]).resolve()
    model_name = doc["model"]
    try:
        model_text = file_rules.read_bytes(model_path).decode("utf-8")
        base = tomllib.loads(model_text)
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        message = getattr(exc, "strerror", None) or str(exc)
        raise ctx.error("model", f"cannot read the model file {model_name}: {message}") from exc

    fixed = ctx.table(doc.get("set", {}), "set")
    for kp, value in _flatten(fixed, ()):
        _merge(base, kp, value, f"set.{key_path_text(kp)}", ctx)

    grid = _parameter_lists(doc, "vary", ctx)
    listed = _parameter_lists(doc, "points", ctx)
    lengths = {len(v) for _, v in listed}
    if len(lengths) > 1:
        kp, first = listed[0]
        odd = next((p, v) for p, v in listed if len(v) != len(first))
        raise ctx.error(f"points.{key_path_text(odd[0])}",
                        f"has {len(odd[1])} values, points.{key_path_text(kp)} has "
                        f"{len(first)} (every list of [points] gives one value per point)")
    seen: set[KeyPath] = set()
    for section, kp, values in [("points", *item) for item in listed] + [
            ("vary", *item) for item in grid]:
        where = f"{section}.{key_path_text(kp)}"
        if kp in seen:
            raise ctx.error(where, "is varied twice (under [points] and [vary])")
        seen.add(kp)
        _check_path(base, kp, values[0], where, model_name, model_path, ctx)
    n = (lengths.pop() if lengths else 1) * _count(grid)
    if n > MAX_POINTS:
        raise ctx.error("vary", f"{n:,} points; a sweep has at most {MAX_POINTS:,}")
    parameters = tuple(kp for kp, _ in listed + grid)
    for column in map(key_path_text, parameters):
        if column in RESERVED_COLUMNS:
            raise ctx.error(column, f"a parameter cannot be named like the result column "
                            f"{column!r}")
    rows = list(zip(*(v for _, v in listed), strict=True)) if listed else [()]
    combos = list(itertools.product(*(v for _, v in grid)))
    points = tuple(tuple(r) + tuple(c) for r in rows for c in combos)

    settings = _setting(ctx.table(doc.get("solve", {}), "solve"), ctx)
    try:  # every point shares this model: its mistakes are the sweep's
        loads_model(to_toml(base), os.fspath(model_path))
    except ModelError as exc:
        raise ctx.error("model", f"{model_name} with [set] does not load: {exc}") from None

    identity = {
        "name": doc["name"],
        "model": hashlib.sha256(model_text.encode()).hexdigest(),
        "set": fixed,
        "parameters": [list(p) for p in parameters],
        "solve": settings.identity(),
    }
    digest = hashlib.sha256(json.dumps(identity, sort_keys=True, default=str).encode())
    return Sweep(name=doc["name"], model_path=model_path, base=base, parameters=parameters,
                 points=points, settings=settings, sweep_id=digest.hexdigest()[:16],
                 source=source)

"""Key paths of a model file: the one place a TOML value is checked for its type and
range, and every fault becomes a :class:`ModelError` naming ``SOURCE: KEY.PATH``.

Used by the model loader (:mod:`mitld_lp.model`), the world tables a model file names
(:mod:`mitld_lp.worlds.loaders`) and the sweep files (:mod:`mitld_lp.sweep.spec`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Any

from mitld_lp import defaults
from mitld_lp.util.text import printable

__all__ = ["ModelError", "KeyContext", "key_path", "toml_text", "type_name", "budgets_table"]


class ModelError(ValueError):
    """A model file is invalid.  The message is ``SOURCE: KEY.PATH: what is wrong``, one
    line of printable characters (a user's names are shown escaped)."""

    def __init__(self, message: str) -> None:
        super().__init__(printable(message))


def _key(part: str) -> str:
    """A key of a key path as TOML writes it: bare, or quoted with escapes."""
    return part if re.fullmatch(r"[A-Za-z0-9_-]+", part) else toml_text(part)


def key_path(path: str, key: str) -> str:
    """``key`` under ``path`` as a key path (``regions.goal``, ``labels."a b"``)."""
    return f"{path}.{_key(key)}" if path else _key(key)


def toml_text(value: Any) -> str:
    """A value the way TOML writes it (``true``, ``"text"``, ``[1, 2]``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list):
        return "[" + ", ".join(toml_text(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_key(k)} = {toml_text(v)}" for k, v in value.items()) + " }"
    return repr(value)


def type_name(value: Any) -> str:
    """What a TOML value is, for a message: ``"an integer"``, ``"a table"``."""
    match value:
        case bool():
            return "a boolean"
        case int():
            return "an integer"
        case float():
            return "a float"
        case str():
            return "a string"
        case list():
            return "an array"
        case dict():
            return "a table"
    return type(value).__name__


class KeyContext:
    """Error reporting for one source, and the budgets a world built while loading gets.

    The one key-path context of the package's TOML files: a model file's (errors are
    :class:`ModelError`) and a sweep file's (``error=SweepError``,
    :mod:`mitld_lp.sweep.spec`); every fault reads ``SOURCE: KEY.PATH: what is wrong``."""

    def __init__(
        self, source: str, max_states: int = defaults.MAX_STATES, max_memory: int | None = None,
        *, error: type[ValueError] = ModelError,
    ) -> None:
        self.source = source
        self.max_states, self.max_memory = max_states, max_memory
        self._error = error

    def error(self, path: str, message: str) -> ValueError:
        where = f"{path}: " if path else ""
        return self._error(f"{self.source}: {where}{message}")

    def table(self, value: Any, path: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.error(path, f"must be a table, got {type_name(value)} {toml_text(value)}")
        return value

    def keys(
        self, table: dict[str, Any], path: str, required: set[str], optional: set[str]
    ) -> None:
        allowed = required | optional
        for k in table:
            if k not in allowed:
                raise self.error(
                    key_path(path, k), f"unknown key (allowed: {', '.join(sorted(allowed))})"
                )
        for k in sorted(required):
            if k not in table:
                raise self.error(key_path(path, k), "missing (required)")

    def string(self, value: Any, path: str) -> str:
        if not isinstance(value, str):
            raise self.error(path, f"must be a string, got {type_name(value)} {toml_text(value)}")
        if not value.strip():
            raise self.error(path, "must not be empty")
        return value

    def number(self, value: Any, path: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(path, f"must be a number, got {type_name(value)} {toml_text(value)}")
        if not math.isfinite(value):
            raise self.error(path, f"must be finite, got {toml_text(value)}")
        return float(value)

    def integer(self, value: Any, path: str) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(path, f"must be an integer, got {type_name(value)} {toml_text(value)}")
        return value

    def array(self, value: Any, path: str) -> list[Any]:
        if not isinstance(value, list):
            raise self.error(path, f"must be an array, got {type_name(value)} {toml_text(value)}")
        return value

    def pair(self, value: Any, path: str) -> tuple[int, int]:
        if not isinstance(value, list) or len(value) != 2:
            raise self.error(path, f"must be a pair [x, y] of integers, got {toml_text(value)}")
        return (self.integer(value[0], f"{path}[0]"), self.integer(value[1], f"{path}[1]"))


#: The ``[budgets]`` a model file may set, with the check of each value.
_BUDGET_KEYS = ("max_states", "max_world_states", "max_automaton_states", "max_memory",
                "time_limit")


def budgets_table(doc: Mapping[str, Any], ctx: KeyContext) -> dict[str, float]:
    """The ``[budgets]`` table: whole numbers >= 1 of states, a size (a number of bytes
    or a text such as ``"4G"``) of memory, a positive number of seconds."""
    if "budgets" not in doc:
        return {}
    table = ctx.table(doc["budgets"], "budgets")
    ctx.keys(table, "budgets", set(), set(_BUDGET_KEYS))
    out: dict[str, float] = {}
    for key, value in table.items():
        where = f"budgets.{key}"
        try:  # the rules every surface applies (mitld_lp.defaults)
            if key == "max_memory":
                out[key] = defaults.check_memory(value, toml_text(value))
            elif key == "time_limit":
                out[key] = defaults.check_seconds(value, toml_text(value))
            else:
                out[key] = defaults.check_count(value, toml_text(value))
        except ValueError as exc:
            raise ctx.error(where, str(exc)) from None
    return out

"""One rule per setting on every surface: the library's Settings, the command line's
option, a model file's [budgets] and a sweep's [solve] accept and refuse the same values
(issue 42: `max_memory=True` and `time_limit=0` were accepted by the library alone)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import pytest

from mitld_lp.cli.arguments import bounded_int, memory_size, seconds
from mitld_lp.model import ModelError, loads_model
from mitld_lp.problem import ProblemError, Settings
from mitld_lp.sweep import SweepError, load_sweep
from mitld_lp.util.clock import Deadline

MODEL = """\
name = "tiny"
spec = "D[mu] b & F(b & F[0,2] A)"
[grid]
size = [3, 2]
start = [0, 0]
[regions]
A = [[2, 1]]
[distributions]
mu = { geometric = 0.5 }
"""

# (setting, value as Python / TOML, as the command line writes it (None: not
# writable there), accepted?) -- by hand: seconds are positive and finite, state
# budgets whole numbers >= 1, memory a whole number of bytes from 1 to 2^63 - 1
CASES = [
    ("time_limit", 0, "0", False),
    ("time_limit", -1.5, "-1.5", False),
    ("time_limit", True, None, False),
    ("time_limit", math.inf, "inf", False),
    ("time_limit", 1e-3, "0.001", True),
    ("time_limit", 30, "30", True),
    ("max_states", 0, "0", False),
    ("max_states", True, None, False),
    ("max_states", 2.5, "2.5", False),
    ("max_states", 10, "10", True),
    ("max_memory", True, None, False),
    ("max_memory", 0, "0", False),
    ("max_memory", 1 << 63, str(1 << 63), False),
    ("max_memory", 4096, "4096", True),
]
_TOML = {True: "true", math.inf: "inf"}


def _toml(value: Any) -> str:
    return _TOML.get(value, repr(value)) if isinstance(value, bool | float) else str(value)


def _library(name: str, value: Any) -> bool:
    try:
        Settings(**{name: value}).checked()
    except ProblemError as exc:
        assert str(exc).startswith(f"{name}: ")
        return False
    return True


def _command_line(name: str, text: str) -> bool:
    parse = {"time_limit": seconds, "max_states": bounded_int(1),
             "max_memory": memory_size}[name]
    try:
        parse(text)
    except argparse.ArgumentTypeError:
        return False
    return True


def _model_file(name: str, value: Any) -> bool:
    try:
        model = loads_model(MODEL + f"[budgets]\n{name} = {_toml(value)}\n")
    except ModelError as exc:
        assert f"budgets.{name}" in str(exc)
        return False
    assert model.budgets[name] == value
    return True


def _sweep(tmp_path: Path, name: str, value: Any) -> bool:
    (tmp_path / "tiny.toml").write_text(MODEL)
    path = tmp_path / "s.toml"
    path.write_text('name = "s"\nmodel = "tiny.toml"\n[vary]\ndistributions.mu.geometric'
                    f" = [0.5]\n[solve]\n{name} = {_toml(value)}\n")
    try:
        load_sweep(path)
    except SweepError as exc:
        assert f"solve.{name}" in str(exc)
        return False
    return True


@pytest.mark.parametrize(("name", "value", "text", "accepted"), CASES)
def test_every_surface_applies_the_same_rule(tmp_path: Path, name: str, value: Any,
                                             text: str | None, accepted: bool) -> None:
    assert _library(name, value) is accepted
    assert _model_file(name, value) is accepted
    assert _sweep(tmp_path, name, value) is accepted
    if text is not None:
        assert _command_line(name, text) is accepted


def test_the_time_left_is_counted_from_the_start_on_the_clock_given() -> None:
    now = [100.0]
    deadline = Deadline.after(5.0, 98.0, clock=lambda: now[0])
    assert deadline.left() == 3.0
    now[0] = 104.0
    assert deadline.left() == 0.0
    assert Deadline.after(None).left() is None


def test_synthesize_takes_the_settings_as_keywords_or_as_one_record() -> None:
    from mitld_lp import synthesize

    model = loads_model(MODEL)
    with pytest.raises(TypeError, match="unknown setting 'epsilom'"):
        synthesize(model, epsilom=0.1)
    with pytest.raises(TypeError, match="not both"):
        synthesize(model, settings=Settings(), epsilon=0.1)
    with pytest.raises(ProblemError, match="time_limit: must be a positive number"):
        synthesize(model, settings=Settings(time_limit=0))

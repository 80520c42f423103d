"""A PRISM world loaded without stormpy: the own parse (:mod:`mitld_lp.worlds.prism_parse`,
:mod:`mitld_lp.worlds.prism_front`) and the own explorer (:mod:`mitld_lp.worlds.prism_explore`).

:func:`own_load` is tried first by :func:`mitld_lp.worlds.prism.load_prism`.  It gives
the tables the stormpy route would build (the same program handed to the same compile and
explorer), or None, and the stormpy route then runs unchanged, where:

* the builder is Storm's (``MITLD_PRISM_BUILDER=storm``) or, under ``auto``, the
  explorer's machine code is not cached (``mitld-lp warm``);
* event effects are asked for, or the world is to be explored as the task reaches it
  (``explore="lazy"``, or ``"auto"`` with a task of bounded horizon whose world is not
  whole within the lazy route's first exploration);
* the file is outside the parsed fragment, has a syntax error, or anything Storm would
  refuse or word (an unknown label, a constant without a value, a type error, a
  variable's range, an update out of range, probabilities that do not sum to 1): Storm's
  route then reports it exactly as before;
* the memory budget does not hold ``max_states`` states of the explorer.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from mitld_lp.logic.fragment import horizon
from mitld_lp.logic.syntax import Formula
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.prism_depth import ExpressionDepth
from mitld_lp.worlds.prism_expr import Expr, PrismTypeError
from mitld_lp.worlds.prism_front import Declined, Program, front_program, resolve
from mitld_lp.worlds.prism_parse import Outside, PrismSyntaxError, parse, parse_expression
from mitld_lp.worlds.prism_program import SizeBound, check_program
from mitld_lp.worlds.prism_tables import Tables

__all__ = ["Owned", "own_load", "own_program"]

log = logging.getLogger("mitld_lp.worlds.prism")

_NAME = re.compile(r"[A-Za-z_]\w*")


@dataclass(frozen=True)
class Owned:
    """What :func:`own_load` built: the tables, the labels chosen, the decided-states
    condition (a PRISM expression, "" for none) and the bound from the ranges."""

    tables: Tables
    chosen: frozenset[str]
    terminal: str
    bound: SizeBound


def own_program(text: str, constants: Mapping[str, Any],
                define: Mapping[str, str]) -> tuple[Program, list[str]]:
    """The front program of ``text`` with ``constants`` and the ``define`` labels, and
    the names of every label defined (the file's, its Boolean formulas that no label
    shadows, then ``define``'s), as the stormpy route defines them.  Raises
    :class:`~mitld_lp.worlds.prism_front.Declined`, ``Outside`` or ``PrismSyntaxError``."""
    parsed = parse(text)
    names = {name for name, _ in parsed.labels} | {name for name, _ in parsed.formulas}
    extra: dict[str, Any] = {}
    for name, text_ in define.items():  # (a name of a formula: the stormpy route's words)
        if (not _NAME.fullmatch(name) or name in names
                or not isinstance(text_, str) or ";" in text_ or '"' in text_):
            raise Declined(f"label {name!r}")
        extra[name] = parse_expression(text_)
    program = front_program(parsed, constants, extra)
    return program, [lab.name for lab in program.labels]


def _condition(program: Program, terminal: str) -> Expr | None:
    """The decided-states condition as an expression over the state variables."""
    if not terminal:
        return None
    return resolve(parse_expression(terminal), program.scope)  # as Storm's, unsimplified


def own_load(text: str, where: str, depth: ExpressionDepth, *, constants: Mapping[str, Any],
             labels: Iterable[str] | None, events: frozenset[str], max_states: int,
             memory: int, define: Mapping[str, str], task: Formula | None,
             explore: str, first: int | None = None) -> Owned | None:
    """The world of the PRISM ``text`` (the file ``where``), or None for the stormpy
    route (module docstring).  Under ``explore="auto"``, a task of bounded horizon is
    given the world only when it is whole within the ``first`` states the lazy route
    explores first (a world Storm's lazy route would also find whole, and give as the
    plain game)."""
    from mitld_lp.worlds import prism_explore
    from mitld_lp.worlds.prism_build import BYTES_PER_STATE
    from mitld_lp.worlds.prism_terminal import decided as decided_when
    from mitld_lp.worlds.prism_terminal import render

    builder = prism_explore.chosen_builder()
    if builder == "storm" or events or explore == "lazy":
        return None
    if explore == "auto" and task is not None and horizon(task) is not None:
        if first is None:
            return None
        max_states = min(max_states, first)  # past it: Storm's lazy route
    if builder == "auto" and not prism_explore.kernel_ready():
        return None
    try:
        program, defined = own_program(text, constants, define)
        chosen = frozenset(defined) if labels is None else frozenset(
            [labels] if isinstance(labels, str) else labels)
        if not chosen <= set(defined):
            return None
        bound = check_program(program, where)
        condition = decided_when(task, frozenset(defined)) if task is not None else False
        terminal = "" if condition is False else render(
            condition, {lab.name: str(lab.expression) for lab in program.labels})
        if terminal and depth.deepest(terminal) is not None:
            terminal = ""
        fits = bound.states <= max_states and bound.states * BYTES_PER_STATE <= memory
        if not fits and max_states * prism_explore.OWN_BYTES_PER_STATE > memory:
            return None
        tables, reason = prism_explore.explore_tables(
            None, program, where, chosen, frozenset(), terminal, max_states,
            condition=_condition(program, terminal))
    except (Declined, Outside, PrismSyntaxError, PrismTypeError, WorldError, RecursionError,
            ZeroDivisionError, OverflowError, ValueError) as exc:  # Storm's route words it
        log.debug("%s: read by Storm, not the own parser: %s", where, exc)
        return None
    if tables is None:
        log.debug("%s: built by Storm, not the own explorer: %s", where, reason)
        return None
    return Owned(tables, chosen, terminal, bound)

"""A JANI MDP (or DTMC) as a :class:`mitld_lp.worlds.prism.PrismGame`, built by Storm.

``load_jani("model.jani", constants={"N": 3}, define={"phi1": "x >= 2"}, task=...)``
parses the file with Storm's JANI parser, gives its open constants their values, builds
the reachable states with Storm's sparse builder (within ``max_states`` and
``max_memory``, as a PRISM world: :mod:`mitld_lp.worlds.prism_bounded`) and copies the
model into the same tables a PRISM world has (:func:`mitld_lp.worlds.prism_tables.read_model`),
so the product, the budgets, ``--exact`` and the answers are the ones of a PRISM world:

* **states** are the values of the model's variables as Storm names them (global ones,
  an automaton's local ``v`` as ``automaton_v``, each automaton's location as
  ``_loc_automaton``); transient variables are not part of a state.
* **propositions**: JANI has no labels.  Its transient Boolean variables are what Storm
  reads as labels (``"goal"`` in a property; a model converted from PRISM keeps its
  labels so), and each of them is a proposition; ``define`` adds more, ``name ->
  expression`` over the variables (and the transient ones), which Storm evaluates on
  every state it builds (its expression labels).
* **robot actions** are the JANI actions of the choices (a synchronisation's result);
  a choice of edges without an action is :data:`SILENT_ACTION`; the self-loop Storm adds
  where no edge is enabled is ``"deadlock"``; two choices of one state with one name get
  the edges they come from appended, ``"silent@wind.gusty"`` (automaton and location;
  ``#k`` for the k-th such edge there, in Storm's order).

States where the task is decided are not expanded (as for a PRISM world, and as Storm
does for a property): Storm's JANI builder takes no expression that stops its
exploration together with expression labels, so the edges' guards are strengthened with
``!decided`` instead; the states reached where it holds keep their labels and get one
self-loop, :data:`~mitld_lp.worlds.prism_tables.DECIDED_ACTION`.  A condition that reads
a transient variable cannot go into a guard; the world is then built whole.

Model types: ``mdp``, and ``dtmc`` where every state has at most one enabled edge (it is
then an MDP with one choice a state; where two edges are enabled a DTMC picks one at
random, which an MDP would make a choice: refused, naming the state).  CTMCs, Markov
automata, timed and hybrid automata and LTSs are refused by name; so is any feature
Storm's sparse builder refuses (its message, one line).  No event effects (``events``):
a PRISM world's.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mitld_lp import defaults
from mitld_lp.logic.syntax import Formula
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.prism import (
    BYTES_PER_STATE,
    PrismGame,
    PrismTooLarge,
    build_within,
    check_budgets,
    stormpy_module,
)
from mitld_lp.worlds.prism_exact import exact_constants
from mitld_lp.worlds.prism_program import storm_error, storm_quiet
from mitld_lp.worlds.prism_tables import Tables, read_model
from mitld_lp.worlds.prism_terminal import decided as decided_when
from mitld_lp.worlds.prism_terminal import render

__all__ = ["JaniFile", "JaniRecipe", "load_jani", "read_jani", "state_bound", "SILENT_ACTION"]

log = logging.getLogger("mitld_lp.worlds.prism")

SILENT_ACTION = "silent"
"""The name of a choice made of edges without an action (JANI's silent action)."""

_TYPES = {"MDP": "mdp", "DTMC": "dtmc", "CTMC": "ctmc", "MA": "Markov automaton",
          "CTMDP": "ctmdp", "LTS": "lts", "TA": "timed automaton",
          "PTA": "probabilistic timed automaton", "STA": "stochastic timed automaton",
          "HA": "hybrid automaton", "PHA": "probabilistic hybrid automaton",
          "SHA": "stochastic hybrid automaton"}


@dataclass(frozen=True)
class JaniFile:
    """A JANI file as Storm parsed it: the model, its properties, its labels (the
    transient Boolean variables, ``name -> name``), the constants it declares, and the
    names of every variable (which a proposition's name must not take)."""

    model: Any
    properties: list[Any]
    labels: dict[str, str]
    constants: frozenset[str]
    variables: frozenset[str]


def read_jani(path: str | os.PathLike[str], where: str | None = None) -> JaniFile:
    """The JANI file at ``path`` parsed by Storm, with its properties; its model type
    checked (an MDP or a DTMC).  Raises :class:`WorldError`."""
    where = os.fspath(path) if where is None else where
    if not Path(path).is_file():
        raise WorldError(f"{where}: no such file")
    stormpy = stormpy_module()
    try:
        with storm_quiet():
            model, properties = stormpy.parse_jani_model(os.fspath(path))
    except (RuntimeError, stormpy.exceptions.StormError) as exc:
        raise storm_error(exc, where) from None
    kind = str(model.model_type).rsplit(".", 1)[-1]
    if kind not in ("MDP", "DTMC"):
        raise WorldError(f"{where}: the model is a {_TYPES.get(kind, kind)}; a game needs "
                         "an mdp (or a dtmc)")
    variables = list(model.global_variables)
    locals_ = [(a.name, v) for a in model.automata for v in a.variables]
    labels = {v.name: v.name for v in variables
              if v.is_transient and v.expression_variable.has_boolean_type()}
    names = {v.name for v in variables} | {f"{a}_{v.name}" for a, v in locals_}
    names |= {v.name for _, v in locals_} | {c.name for c in model.constants}
    return JaniFile(model, list(properties), labels,
                    frozenset(c.name for c in model.constants), frozenset(names))


@dataclass(frozen=True)
class JaniRecipe:
    """How a JANI world was built, to build it again in exact arithmetic
    (:meth:`build_exact`, for ``--exact``)."""

    path: str
    where: str
    constants: Mapping[str, bool | int | float] = field(default_factory=dict)
    define: Mapping[str, str] = field(default_factory=dict)
    terminal: str = ""

    def build_exact(self) -> Any:
        stormpy = stormpy_module()
        given = exact_constants(stormpy, self.constants)
        build = _Build(stormpy, read_jani(self.path, self.where), self.where, given,
                       dict(self.define), self.terminal)
        try:
            return build.storm(exact=True)
        except WorldError as exc:
            raise WorldError(f"{exc} (in Storm's exact build: the exact answer takes the "
                             "probabilities as written)") from None


class _Build:
    """One JANI model prepared for Storm's builder: constants given, the labels
    ``define`` adds as Storm's expression labels, the guards strengthened with
    ``!terminal``."""

    def __init__(self, stormpy: Any, file: JaniFile, where: str, given: Mapping[str, Any],
                 define: dict[str, str], terminal: str) -> None:
        self.stormpy, self.where, self.file = stormpy, where, file
        errors = (RuntimeError, stormpy.exceptions.StormError)
        model = file.model
        if given:
            try:
                with storm_quiet():
                    model = stormpy.instantiate_constants(model, dict(given))[0]
            except errors as exc:
                raise storm_error(exc, where) from None
        self.kind = str(model.model_type).rsplit(".", 1)[-1]
        if self.kind == "DTMC":
            from stormpy.developer import JaniModelType  # pyright: ignore

            model.set_model_type(JaniModelType.MDP)  # checked after the build
        self.model = model
        # each label's formula: Storm builds an expression label named by its printing
        self.expressions: dict[str, str] = {}
        formulas = []
        for name, text in define.items():
            formula = self._expression(text, f"label {name!r} = {text!r}")
            formulas.append(formula)
            self.expressions[name] = str(formula.subformula.subformula)
        self.decided: str | None = None
        if terminal:
            formula = self._expression(terminal, "the states where the task is decided")
            expression = formula.subformula.subformula.get_expression()
            if {v.name for v in expression.get_variables()} & set(file.labels):
                log.info("%s: the states where the task is decided read a transient "
                         "variable; all states are expanded", where)
            else:
                negated = self._expression(f"!({terminal})", "!decided")
                guard = negated.subformula.subformula.get_expression()
                for automaton in model.automata:
                    for edge in automaton.edges:
                        template = edge.template_edge
                        template.guard = stormpy.expressions.Expression.And(
                            template.guard, guard)
                formulas.append(formula)
                self.decided = str(formula.subformula.subformula)
        # one formula would also make Storm stop at its target: never one
        self.formulas = formulas * 2 if len(formulas) == 1 else formulas
        self.origins = _needs_origins(model)

    def _expression(self, text: str, what: str) -> Any:
        """``Pmax=? [F (text)]`` parsed against the model (its atomic subformula is the
        expression, and Storm's label of it is its printing)."""
        stormpy = self.stormpy
        try:
            with storm_quiet():
                formula = stormpy.parse_properties(f"Pmax=? [F ({text})]",
                                                   self.model)[0].get_raw_formula()
        except (RuntimeError, stormpy.exceptions.StormError) as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else "cannot parse"
            raise WorldError(f"{self.where}: {what}: {first}") from None
        import stormpy.logic as logic  # pyright: ignore[reportMissingImports]

        if not isinstance(formula.subformula.subformula, logic.AtomicExpressionFormula):
            raise WorldError(f"{self.where}: {what}: not one expression over the variables")
        return formula

    def storm(self, exact: bool = False) -> Any:
        """Storm's sparse build (rational numbers when ``exact``)."""
        stormpy = self.stormpy
        o = stormpy.BuilderOptions(self.formulas) if self.formulas else stormpy.BuilderOptions()
        o.set_exploration_checks(True)
        o.set_build_all_labels()
        o.set_build_choice_labels()
        o.set_build_state_valuations()
        if self.origins:
            o.set_build_choice_origins()
        build = stormpy.build_model[stormpy.Rational] if exact else stormpy.build_model
        try:
            with storm_quiet():
                model = build(self.model, options=o)
        except (RuntimeError, stormpy.exceptions.StormError) as exc:
            raise storm_error(exc, self.where) from None
        labeling = model.labeling
        for name, label in self.expressions.items():  # the expression labels, named
            labeling.add_label(name)
            labeling.set_states(name, labeling.get_states(label))
        return model

    def tables(self, chosen: frozenset[str], max_states: int) -> Tables:
        model = self.storm()
        where = self.where
        if model.nr_states > max_states:
            raise PrismTooLarge(
                f"{where}: Storm explored {model.nr_states:,} states, more than max_states "
                f"= {max_states:,}: raise max_states (--max-world-states)")
        origins = model.choice_origins if self.origins else None
        names = _EdgeNames(self.model)

        def origin(choice: int) -> str:
            """The edges a choice comes from, ``wind.gusty``."""
            if origins is None:
                raise AssertionError("two choices of one name without two such edges")
            edges = sorted(origins.get_edge_index_set(choice))
            return "+".join(names(self.model.decode_automaton_and_edge_index(e))
                            for e in edges) or "deadlock"

        tables = read_model(model, where, chosen, frozenset(), {}, origin, self.decided,
                            silent=SILENT_ACTION, hidden=frozenset(self.file.labels))
        if self.kind == "DTMC":
            import numpy as np

            two = np.flatnonzero(np.diff(tables.choices) > 1)
            if two.size:
                s = int(two[0])
                shown = ", ".join(f"{k}={v}" for k, v in zip(tables.variables,
                                                            tables.states[s], strict=True))
                raise WorldError(f"{where}: a dtmc with two edges enabled at state [{shown}]"
                                 ": Storm picks one at random there, a game would make it "
                                 "a choice (write the model as an mdp)")
        return tables


class _EdgeNames:
    """``automaton.location`` of an edge (``#k`` when the location has several edges of
    its action, k in Storm's order from 1)."""

    def __init__(self, model: Any) -> None:
        self.model = model

    def __call__(self, index: tuple[int, int]) -> str:
        automaton = self.model.automata[index[0]]
        edges = list(automaton.edges)
        edge = edges[index[1]]
        location = automaton.locations[edge.source_location_index].name
        same = [k for k, e in enumerate(edges)
                if e.source_location_index == edge.source_location_index
                and e.action_index == edge.action_index]
        mark = f"#{same.index(index[1]) + 1}" if len(same) > 1 else ""
        return f"{automaton.name}.{location}{mark}"


def _needs_origins(model: Any) -> bool:
    """Whether two choices of one state may have one name: two silent edges anywhere,
    or two edges of one action from one location of an automaton."""
    silent = 0
    for automaton in model.automata:
        seen = set()
        for edge in automaton.edges:
            key = (edge.source_location_index, edge.action_index)
            if key in seen:
                return True
            seen.add(key)
            silent += edge.has_silent_action()
    return silent > 1


def _check_constants(file: JaniFile, given: Mapping[str, Any], where: str) -> None:
    declared = {c.name: c for c in file.model.constants}
    for name, value in given.items():
        if name not in declared:
            known = ", ".join(sorted(declared)) or "none"
            raise WorldError(f"{where}: constant {name!r} is not declared (constants: {known})")
        if declared[name].defined:
            raise WorldError(f"{where}: constant {name!r} already has a value in the file; "
                             "only undefined constants can be given")
        variable = declared[name].expression_variable
        if variable.has_boolean_type() != isinstance(value, bool):
            raise WorldError(f"{where}: constant {name!r} must be "
                             f"{'a boolean' if variable.has_boolean_type() else 'a number'}"
                             f", got {value!r}")
        if variable.has_integer_type() and not isinstance(value, int):
            raise WorldError(f"{where}: constant {name!r} must be an integer, got {value!r}")
    missing = sorted(n for n, c in declared.items() if not c.defined and n not in given)
    if missing:
        raise WorldError(f"{where}: constants {', '.join(missing)} have no value in the "
                         "file; give them with constants={...}")


def state_bound(model: Any) -> int | None:
    """The product of the variables' ranges and the automata's locations, when every
    variable is bounded or Boolean (None otherwise): an upper bound on the states."""
    total = 1
    variables = [v for v in model.global_variables if not v.is_transient]
    variables += [v for a in model.automata for v in a.variables if not v.is_transient]
    for v in variables:
        kind = v.type
        if v.expression_variable.has_boolean_type():
            total *= 2
        elif kind.is_bounded_type and kind.lower_bound.is_literal() \
                and kind.upper_bound.is_literal():
            total *= max(kind.upper_bound.evaluate_as_int() - kind.lower_bound.evaluate_as_int()
                         + 1, 1)
        else:
            return None
    for automaton in model.automata:
        total *= max(len(automaton.locations), 1)
    return total


def load_jani(
    path: str | os.PathLike[str],
    *,
    constants: Mapping[str, bool | int | float] | None = None,
    define: Mapping[str, str] | None = None,
    task: Formula | None = None,
    max_states: int = defaults.MAX_STATES,
    max_memory: int | None = None,
) -> PrismGame:
    """Build the JANI model at ``path`` with Storm and return it as a game (module
    docstring).  ``constants``, ``define``, ``task``, ``max_states`` and ``max_memory``
    as for :func:`mitld_lp.worlds.prism.load_prism`.  Raises
    :class:`mitld_lp.worlds.WorldError` (:class:`~mitld_lp.worlds.prism.PrismTooLarge`
    for a budget)."""
    memory = check_budgets(max_states, max_memory)
    where = os.fspath(path)
    stormpy = stormpy_module()
    file = read_jani(path, where)
    given = dict(constants or {})
    _check_constants(file, given, where)
    define = dict(define or {})
    for name in define:
        if name in file.labels or name in file.variables:
            raise WorldError(f"label {name!r}: {where} already has a variable {name!r}")
    labels = frozenset(file.labels) | frozenset(define)
    condition = decided_when(task, labels) if task is not None else False
    terminal = "" if condition is False else render(
        condition, {**file.labels, **define})
    build = _Build(stormpy, file, where, given, define, terminal)
    bound = state_bound(build.model)

    def work() -> Tables:
        return build.tables(labels, max_states)

    fits = bound is not None and bound <= max_states and bound * BYTES_PER_STATE <= memory
    note = ("the variables' ranges unbounded" if bound is None else
            f"{bound:,} valuations of the variables' ranges and the locations")
    tables = build_within(work, where, fits, note, max_states, memory)
    log.info("%s: %d states explored, %d not expanded (task decided: %s), labels %s",
             where, len(tables.states), tables.decided, build.decided or "never",
             sorted(labels))
    return PrismGame(
        source=where, variables=tables.variables, states=tables.states,
        initial=tables.states[tables.initial], proposition_names=labels, effects={},
        terminal=terminal if build.decided else "", decided=tables.decided,
        normalised=tables.normalised, _tables=tables,
        recipe=JaniRecipe(str(Path(path).resolve()), where, given, define, terminal),
    )

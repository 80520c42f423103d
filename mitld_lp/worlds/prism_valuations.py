"""A PRISM world's state valuations, made by Storm when first read.

Storm's state valuations are a sixth of its build (csma 4-2 of QVBS, 608,082 states:
6.3 s with them, 5.3 s without), and a solve reads none of them: the product numbers
the world's states as Storm does and asks for a state's values only to name it (a
policy's table, a controller, an export with valuations, an error message).  So a world
built whole (:func:`mitld_lp.worlds.prism_build.build_tables` without a state limit) and
without event effects (the product reads such a world state by state, by name) is built
without them, and its :attr:`~mitld_lp.worlds.prism.PrismGame.states` are
:class:`DeferredValuations`: the variables and the initial state come from Storm's
program (:func:`program_head`; where it has an ``init`` block, from a build of the
initial state alone, :func:`head`), and the first other state asked for makes Storm
build the world again, with its valuations and the same options (:func:`rebuild`):
Storm numbers states in the order its breadth-first search finds them, so the second
build numbers them alike, which is checked (states, choices, the initial state).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Any

import numpy as np

from mitld_lp.worlds import WorldError
from mitld_lp.worlds.prism_exact import PrismRecipe, program_of
from mitld_lp.worlds.prism_origins import needs_origins
from mitld_lp.worlds.prism_program import (
    builder_options,
    storm_build,
    storm_error,
    storm_quiet,
)
from mitld_lp.worlds.prism_tables import Valuations, read_export, valuations_of

__all__ = ["ValuationRecipe", "DeferredValuations", "head", "program_head", "rebuild"]

State = tuple[Hashable, ...]


@dataclass(frozen=True, slots=True)
class ValuationRecipe:
    """How to build a world again with its valuations: its :class:`PrismRecipe`,
    whether Storm's exploration checks were on, and what the first build found (to
    check that the second numbers the states alike)."""

    recipe: PrismRecipe
    checks: bool
    n_states: int
    n_choices: int
    initial: int


def quiet_build(stormpy: Any, program: Any, options: Any, where: str, limit: int | None) -> Any:
    """Storm's build of ``program`` with ``options`` (at most ``limit`` states), its
    printing silenced and its errors raised as ours, naming ``where``."""
    try:
        with storm_quiet():
            return storm_build(stormpy, program, options, float, limit)
    except (RuntimeError, stormpy.exceptions.StormError) as exc:
        raise storm_error(exc, where, program) from None


def head(stormpy: Any, program: Any, terminal: str, origins: bool, where: str,
         ) -> tuple[tuple[str, ...], int, State, tuple[int, ...]]:
    """``(variables, initial, its values, Boolean columns)`` from Storm's build of the
    initial state alone (one state found, none expanded), with its valuations."""
    options = builder_options(stormpy, program, terminal, checks=True, origins=origins)
    model = quiet_build(stormpy, program, options, where, 1)
    variables, states = valuations_of(model, packed=read_export(model, where)[1])
    initial = int(model.initial_states[0])
    return variables, initial, states[initial], states.booleans


def program_head(plain: Any) -> tuple[tuple[str, ...], State, tuple[int, ...]] | None:
    """:func:`head`'s ``(variables, the initial state's values, Boolean columns)`` read
    from Storm's program itself (``plain``: its constants substituted), without a build
    (Storm's build of the initial state alone costs some 25 ms, its builder's set-up):
    the state variables by name, the order of Storm's valuations, each with its initial
    value (Storm's parser gives every variable one, and turns a variable no command
    changes into a constant).  None where the program has an ``init`` block or a value
    does not evaluate: :func:`head` builds the initial state then.  The values Storm
    builds later are taken by name and checked against these
    (:meth:`DeferredValuations.take`)."""
    try:
        if plain.has_initial_states_expression:
            return None
        values: dict[str, Hashable] = {}
        booleans: set[str] = set()
        pairs = [(v, True) for v in plain.global_boolean_variables]
        pairs += [(v, False) for v in plain.global_integer_variables]
        for module in plain.modules:
            pairs += [(v, True) for v in module.boolean_variables]
            pairs += [(v, False) for v in module.integer_variables]
        for var, boolean in pairs:
            if var.name in values:
                return None
            e = var.initial_value_expression
            values[var.name] = bool(e.evaluate_as_bool()) if boolean else int(
                e.evaluate_as_int())
            if boolean:
                booleans.add(var.name)
    except Exception:  # noqa: BLE001 - any doubt: Storm's build of the initial state
        return None
    if not values:
        return None
    order = tuple(sorted(values))
    return (order, tuple(values[name] for name in order),
            tuple(j for j, name in enumerate(order) if name in booleans))


def rebuild(make: ValuationRecipe) -> tuple[tuple[str, ...], Valuations]:
    """The world's variables and valuations from Storm's build of ``make.recipe`` with
    them (the same options as the first build otherwise); :class:`WorldError` when that
    build numbers the states otherwise."""
    import stormpy  # the world was built by it: installed

    where = make.recipe.where
    program = program_of(stormpy, make.recipe, exact=False)
    options = builder_options(stormpy, program, make.recipe.terminal, checks=make.checks,
                              origins=needs_origins(program))
    model = quiet_build(stormpy, program, options, where, None)
    found = (model.nr_states, model.nr_choices, int(model.initial_states[0]))
    if found != (make.n_states, make.n_choices, make.initial):
        raise WorldError(f"{where}: Storm's build with valuations has {found[0]:,} states "
                         f"and {found[1]:,} choices, its first build {make.n_states:,} and "
                         f"{make.n_choices:,}: the states cannot be named")
    return valuations_of(model, packed=read_export(model, where)[1])


class DeferredValuations(Valuations):
    """:class:`~mitld_lp.worlds.prism_tables.Valuations` whose values Storm builds
    when first read (:func:`rebuild`); the number of states and the initial state's
    values are known before."""

    def __init__(self, make: ValuationRecipe, known: State, booleans: tuple[int, ...],
                 variables: tuple[str, ...]) -> None:
        self.make = make
        self.known = known  # the initial state's values
        self.booleans = booleans
        self.variables = variables  # the order of the values' columns
        self._values: np.ndarray | None = None
        # Storm's second build of another part made when first read (the choices' names:
        # mitld_lp.worlds.prism_names), asked to make the values in the same build
        self.joint: Callable[[], None] | None = None

    @property  # type: ignore[override]
    def values(self) -> np.ndarray:
        if self._values is None and self.joint is not None:
            self.joint()
        if self._values is None:
            self.take(*rebuild(self.make))
        assert self._values is not None
        return self._values

    def take(self, order: tuple[str, ...], built: Valuations) -> None:
        """Keep the values of Storm's second build, whose columns are the variables
        ``order``, in this one's order of the variables; checked: the same variables,
        the same Boolean ones and the same initial state."""
        where = self.make.recipe.where
        if sorted(order) != sorted(self.variables) or (
                {order[j] for j in built.booleans}
                != {self.variables[j] for j in self.booleans}):
            raise WorldError(f"{where}: Storm's build with valuations has other variables "
                             f"({', '.join(order)}) than its first build "
                             f"({', '.join(self.variables)})")
        at = [order.index(name) for name in self.variables]
        values = built.values if at == list(range(len(at))) else np.ascontiguousarray(
            built.values[:, at])
        first = Valuations(values, self.booleans)[self.make.initial]
        if first != self.known:
            raise WorldError(f"{where}: Storm's build with valuations starts in "
                             f"{first}, the program in {self.known}")
        self._values = values

    @property
    def built(self) -> bool:
        """Whether Storm has built the values yet."""
        return self._values is not None

    def __len__(self) -> int:
        return self.make.n_states

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, int | np.integer) and int(i) in (self.make.initial,
                                                          self.make.initial - len(self)):
            return self.known
        return super().__getitem__(i)

    def __repr__(self) -> str:
        shown = "built" if self.built else "built when first read"
        return f"DeferredValuations(<{len(self)} states, {shown}>)"

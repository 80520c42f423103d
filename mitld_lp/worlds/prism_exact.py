"""A PRISM world's probabilities as the file writes them: Storm's exact build.

The world the product reads (:mod:`mitld_lp.worlds.prism`) holds Storm's floating-point
build.  An exact answer (:mod:`mitld_lp.exact`) needs the probabilities as the PRISM file
writes them (``0.001`` is ``1/1000``, ``1-p`` with ``p = 0.3`` is ``7/10``): Storm builds
the same program once more in rational arithmetic (``build_model[stormpy.Rational]``,
Storm's own parser and exact expression evaluation, the same builder options, its
exploration checks on: a command whose probabilities do not sum to exactly 1 is refused
here, where the floating-point world accepted a sum within PRISM's tolerance), and each
branch of the world's table gets its rational probability.

The two builds must be the same MDP: the same number of states, the same choices per
state, the same successors per choice in the same order (Storm explores a program in
one order whatever the number type); anything else is refused, naming the first
difference.  A float constant of the program is given to the exact build as the number
it stands for (:func:`mitld_lp.util.decimals.exact_value`: its text when read from a
model file).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from mitld_lp.util.decimals import exact_value
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.prism_origins import needs_origins
from mitld_lp.worlds.prism_program import (
    builder_options,
    labelled_program,
    storm_error,
    storm_quiet,
    with_constants,
)
from mitld_lp.worlds.prism_tables import Tables

__all__ = ["PrismRecipe", "exact_probabilities", "exact_build", "exact_constants",
           "program_of"]


@dataclass(frozen=True, slots=True)
class PrismRecipe:
    """How a PRISM world was built, to build it again: the file (``path``, absolute;
    ``where`` as the user named it, for messages), the values of its open constants, the
    labels ``define`` added, and the states not expanded (``terminal``, a PRISM
    expression; "" for none)."""

    path: str
    where: str
    constants: Mapping[str, bool | int | float] = field(default_factory=dict)
    define: Mapping[str, str] = field(default_factory=dict)
    terminal: str = ""


def exact_constants(stormpy: Any, constants: Mapping[str, Any]) -> dict[str, Any]:
    """``constants`` for Storm's exact build: a float as the number it stands for
    (:func:`mitld_lp.util.decimals.exact_value`: its text when read from a file), a
    Storm rational."""
    given: dict[str, Any] = {}
    for name, value in constants.items():
        if isinstance(value, float):  # the number as written, not its binary rounding
            exact = exact_value(value)
            value = stormpy.Rational(f"{exact.numerator}/{exact.denominator}")
        given[name] = value
    return given


def program_of(stormpy: Any, recipe: PrismRecipe, *, exact: bool = True) -> Any:
    """The program as the world's build prepared it, its constants exact (``exact``)
    or as given."""
    where = recipe.where
    program = labelled_program(stormpy, Path(recipe.path), recipe.path, recipe.define, where)
    given = exact_constants(stormpy, recipe.constants) if exact else dict(recipe.constants)
    return with_constants(stormpy, program, given, where)


def exact_build(recipe: PrismRecipe) -> Any:
    """Storm's exact build of ``recipe`` (the world's program, the same builder options)."""
    import stormpy  # the world was built by it: installed

    program = program_of(stormpy, recipe)
    options = builder_options(stormpy, program, recipe.terminal, checks=True,
                              origins=needs_origins(program))
    try:
        with storm_quiet():
            return stormpy.build_model[stormpy.Rational](program, options=options)
    except (RuntimeError, stormpy.exceptions.StormError) as exc:
        raise WorldError(f"{str(storm_error(exc, recipe.where))} (in Storm's exact build: "
                         "the exact answer takes the probabilities as written)") from None


def exact_probabilities(recipe: Any, tables: Tables) -> tuple[Fraction, ...]:
    """The rational probability of each branch of ``tables`` (the world's floating-point
    build), in its order, from Storm's exact build of ``recipe`` (module docs; a recipe
    with a ``build_exact()`` of its own, a JANI world's, builds it so).  Raises
    :class:`mitld_lp.worlds.WorldError` when Storm refuses the exact build or when the
    two builds differ."""
    where = recipe.where
    model = recipe.build_exact() if hasattr(recipe, "build_exact") else exact_build(recipe)
    n, m = len(tables.states), int(tables.choices[-1])
    if (model.nr_states, model.nr_choices) != (n, m) or int(model.initial_states[0]) != \
            tables.initial:
        raise WorldError(f"{where}: Storm's exact build has {model.nr_states:,} states and "
                         f"{model.nr_choices:,} choices, its floating-point build {n:,} and "
                         f"{m:,}: the exact answer needs one MDP")
    matrix = model.transition_matrix
    groups = [matrix.get_row_group_start(s) for s in range(n)]
    if not np.array_equal(np.asarray(groups, dtype=np.int64), tables.choices[:-1]):
        raise WorldError(f"{where}: Storm's exact build groups its choices differently "
                         "from its floating-point build")
    out: list[Fraction] = []
    targets = tables.targets.tolist()
    branches = tables.branches.tolist()
    for c in range(m):
        row = [(e.column, Fraction(str(e.value))) for e in matrix.get_row(c)]
        row = [(j, p) for j, p in row if p != 0]  # as the table drops them
        lo, hi = branches[c], branches[c + 1]
        if [j for j, _ in row] != targets[lo:hi]:
            raise WorldError(f"{where}: choice {c} of Storm's exact build has other "
                             "successors than its floating-point build (a probability "
                             "that rounds to 0 in floating point?)")
        out.extend(p for _, p in row)
    return tuple(out)

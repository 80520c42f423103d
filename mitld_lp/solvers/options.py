"""How a solve is run: the solver, its backend, its accuracy and its deadline, as one
record (:class:`SolveOptions`); its deadline is the package's one
:class:`~mitld_lp.util.clock.Deadline` (the time left computed in one place).
What the options mean to a given solver (its keywords) is the business of the module
that calls it (:mod:`mitld_lp.solvers.lp_backends`)."""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from mitld_lp.util.clock import Deadline

__all__ = ["Deadline", "Layout", "SolveOptions"]


class Layout(enum.StrEnum):
    """How the occupancy LP of :func:`mitld_lp.solvers.solve_lp` is laid out for the
    solver."""

    BLOCKS = "blocks"
    """Block by block, the strongly connected components in topological order, each
    block's answer polished exactly (:mod:`mitld_lp.solvers.lp`)."""
    WHOLE = "whole"
    """One monolithic LP (the one :func:`mitld_lp.solvers.write_lp` exports)."""


@dataclass(frozen=True, slots=True)
class SolveOptions:
    """How every LP of one solve is solved.

    Attributes:
        solver: the LP solver's name (``"CLARABEL"``, ``"HIGHS"``, ...).
        backend: ``"direct"`` (Clarabel on the matrices) or ``"cvxpy"``.
        tol: the solver's gap and feasibility tolerance.
        precision: relative precision with which exact values tell tight choices apart
            (``None``: the tolerance alone).
        deadline: when the solve must stop.
        extra: the caller's own solver keywords (they override the tolerance ones).
        greedy: a block with sound bounds and at least
            :data:`mitld_lp.solvers.lp_blocks.GREEDY_MIN_CHOICES` choices is first
            answered by their greedy policy where the LP's optimality conditions
            certify it, without a solver call (:mod:`mitld_lp.solvers.greedy_block`);
            ``False``: every block is solved.
    """

    solver: str
    backend: str
    tol: float
    precision: float | None = None
    deadline: Deadline = Deadline()
    extra: Mapping[str, Any] = field(default_factory=dict)
    greedy: bool = True

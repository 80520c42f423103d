"""How a solve is run: the solver, its backend, its accuracy and its deadline, as one
record (:class:`SolveOptions`), and the time left computed in one place
(:class:`Deadline`).  What the options mean to a given solver (its keywords) is the
business of the module that calls it (:mod:`mitld_lp.solvers.lp_backends`)."""

from __future__ import annotations

import enum
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Deadline", "Layout", "SolveOptions"]


@dataclass(frozen=True, slots=True)
class Deadline:
    """A point in time (a :func:`time.perf_counter` value; ``inf``: no time limit) and
    the time left until it, the one way every solver reads a time limit."""

    at: float = math.inf

    @classmethod
    def after(cls, seconds: float | None, start: float | None = None) -> Deadline:
        """``seconds`` after ``start`` (now if ``None``); no deadline if ``seconds`` is
        ``None``."""
        if seconds is None:
            return cls()
        return cls((time.perf_counter() if start is None else start) + seconds)

    @property
    def limited(self) -> bool:
        """Whether there is a time limit at all."""
        return math.isfinite(self.at)

    def remaining(self) -> float | None:
        """Seconds left (0 once past), ``None`` without a time limit."""
        if not self.limited:
            return None
        return max(self.at - time.perf_counter(), 0.0)

    def passed(self) -> bool:
        """Whether the deadline has been reached."""
        return time.perf_counter() >= self.at


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
    """

    solver: str
    backend: str
    tol: float
    precision: float | None = None
    deadline: Deadline = Deadline()
    extra: Mapping[str, Any] = field(default_factory=dict)

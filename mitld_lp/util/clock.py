"""The time left before a time limit, computed in one place (:class:`Deadline`): the
routes' solves, the solvers' options (:class:`mitld_lp.solvers.options.SolveOptions`),
the command line's options and the exact stage read it here."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["Deadline"]


@dataclass(frozen=True, slots=True)
class Deadline:
    """The moment ``at`` (on ``clock``) past which work stops; ``inf``: no limit."""

    at: float = math.inf
    clock: Callable[[], float] = time.perf_counter

    @classmethod
    def after(cls, seconds: float | None, start: float | None = None,
              clock: Callable[[], float] = time.perf_counter) -> Deadline:
        """``seconds`` after ``start`` (default now, on ``clock``); ``None``: no limit."""
        if seconds is None:
            return cls(math.inf, clock)
        return cls((clock() if start is None else start) + seconds, clock)

    def left(self) -> float | None:
        """Seconds left, at least 0 (``None``: no limit), as the solvers'
        ``time_limit`` takes them."""
        if self.at == math.inf:
            return None
        return max(0.0, self.at - self.clock())

    @property
    def limited(self) -> bool:
        """Whether there is a time limit at all."""
        return math.isfinite(self.at)

    def passed(self) -> bool:
        """Whether the deadline has been reached."""
        return self.clock() >= self.at

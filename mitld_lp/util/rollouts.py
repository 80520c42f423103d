"""What every Monte-Carlo rollout shares (:mod:`mitld_lp.running.simulate` for a fully
observed controller, :mod:`mitld_lp.sensing.observe` for one that acts on sensor
reports): the result record, the Wilson interval, a successor drawn from a world's
distribution, the checks of the counts.  Below both (NumPy alone), so that neither
package imports the other to share them."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["SimulationResult", "wilson", "sample_successor", "check_count"]


@dataclass(frozen=True, slots=True)
class SimulationResult:
    runs: int
    successes: int
    estimate: float
    ci_low: float
    ci_high: float
    beyond_model: int  # runs in which an event came later than its truncation point
    undecided: int  # runs stopped at max_steps without a verdict (counted as failures)
    seed: int | None
    horizon: int = 0  # max_steps: the steps each run was watched for a violation
    kept: int = 0  # successes that were keeping a safety part, unviolated, at the horizon


def wilson(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """The Wilson score interval of ``k`` successes in ``n`` runs (95% by default).

    In exact arithmetic its lower end is 0 when ``k = 0`` and its upper end 1 when
    ``k = n``; the floating-point formula misses them by an ulp either way, which would
    exclude a true value of exactly 0 or 1, so the ends are set there exactly.
    """
    if n == 0:
        return 0.0, 1.0
    p = k / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    low = 0.0 if k == 0 else max(0.0, centre - half)
    high = 1.0 if k == n else min(1.0, centre + half)
    return low, high


def sample_successor(rng: np.random.Generator, succ) -> Any:
    u = rng.random()
    acc = 0.0
    for s, p in succ:
        acc += p
        if u < acc:
            return s
    return succ[-1][0]


def check_count(name: str, value: object, low: int, high: int | None) -> None:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise ValueError(f"{name}: must be an integer, got {value!r}")
    if value < low or (high is not None and value > high):
        bound = f"in {low}..{high:,}" if high is not None else f">= {low}"
        raise ValueError(f"{name}: must be {bound}, got {value!r}")

"""The certificates' last check (:mod:`mitld_lp.solvers.certify`): the policy is optimal
in every state, its certified bounds and the optimum's within the precision of each
other everywhere (:func:`everywhere`), read a batch of states at a time."""

from __future__ import annotations

import numpy as np

from mitld_lp.checks import Check

__all__ = ["EVERYWHERE", "EVERYWHERE_BATCH", "everywhere"]

EVERYWHERE_BATCH = 1 << 16
"""States read at a time by :func:`everywhere` (its memory bound, not its verdict)."""

EVERYWHERE = "policy optimal in every state"
"""The name of :func:`everywhere`'s check."""


def everywhere(lower: np.ndarray, upper: np.ndarray, initial: int, precision: float, *,
               complement: bool = False) -> Check:
    """The check that the policy is optimal in every state, not only where it goes: the
    certified bounds of its value and of the optimum (one of them the policy's) are
    within ``precision`` of each other in every state, relative to the larger of the
    state's value and the initial state's (a state far rarer than the answer is held
    to the answer's scale).  ``complement``: the answer is ``1 -`` the values (a
    minimum read back from its complement's maximum), the scale too.

    Read :data:`EVERYWHERE_BATCH` states at a time: the gap, the scale and their
    product with the precision of every state at once were three floats a state, the
    certificate's traced peak on QVBS csma 4-2.  Each state's test is the same
    operations on the same operands, and the worst state the first of the largest
    ratio, as one pass over every state finds it."""
    n = lower.size
    # ``value[initial]`` of the whole vector: the same operation on the same operands
    at_initial = (1.0 - upper[initial]) if complement else lower[initial]
    count, worst, top = 0, -1, None
    for a in range(0, n, EVERYWHERE_BATCH):
        z = min(a + EVERYWHERE_BATCH, n)
        gap = upper[a:z] - lower[a:z]
        value = 1.0 - upper[a:z] if complement else lower[a:z]
        scale = np.maximum(value, at_initial)
        del value
        bad = np.flatnonzero(gap > precision * scale)
        if bad.size:
            count += bad.size
            ratio = gap[bad] / np.maximum(scale[bad], 1e-300)
            k = int(np.argmax(ratio))
            if top is None or ratio[k] > top:  # strictly: the first of the largest
                top, worst = ratio[k], a + int(bad[k])
        del gap, scale, bad
    return Check(EVERYWHERE, count == 0, (
        f"certified bounds of the policy's value and of the optimum within {precision:g} "
        f"(relative) in all {n} states" if count == 0 else
        f"{count} states apart by more than {precision:g} (relative), e.g. state "
        f"{worst}: [{float(lower[worst])!r}, {float(upper[worst])!r}]"))

"""A sensor with false alarms, a law known only within a band whose laws surely happen,
and constraints, ``then`` or the trade-off curve (issue 43).  Here: nature's least
probability of reaching a target on an interval chain whose runs wait in a loop they
leave with a tiny probability, worked out by hand."""

from __future__ import annotations

import numpy as np


def test_a_run_left_in_a_loop_for_ever_almost_never_reaches_the_target_surely() -> None:
    """A controller that waits for ever on a sensor with false alarms leaves its loop
    with a tiny probability (an interior-point solution's residue): 40 states in a row,
    each left for the next with probability 1e-9 a step (nature choosing that or 2e-9),
    the last into the target, and a side state nature may keep out of it for ever.
    Every run from the row reaches the target, by the graph alone (value 1, where
    value iteration from below would need billions of rounds); the side state's value
    is 0, and a state that nature may send there with 1/2 is worth 1/2."""
    import scipy.sparse as sp

    from mitld_lp.running.band_chain import BandChain
    from mitld_lp.running.sensed_band_chain import reach_min

    n = 40  # the row 0..n-1, the target n, the side state n + 1, the fork n + 2
    rows: list[list[dict[int, float]]] = [
        [{i: 1 - e, i + 1: e} for e in (1e-9, 2e-9)] for i in range(n)]
    rows += [[{n: 1.0}], [{n + 1: 1.0}, {n: 1.0}], [{0: 0.5, n + 1: 0.5}]]
    target = np.zeros(len(rows), dtype=bool)
    target[n] = True

    def at(start: int) -> float:  # the chain with ``start`` as its state 0
        order = [start, *(s for s in range(len(rows)) if s != start)]
        perm = np.argsort(order)  # old state -> new
        grouped = [[{int(perm[j]): p for j, p in r.items()} for r in rows[s]]
                   for s in order]
        f = [r for here in grouped for r in here]
        m = sp.csr_array(([p for r in f for p in r.values()],
                          ([i for i, r in enumerate(f) for _ in r],
                           [j for r in f for j in r])), shape=(len(f), len(order)))
        g = np.cumsum([0] + [len(h) for h in grouped])
        chain = BandChain(m, m.data.copy(), g, tuple(str(i) for i in range(len(f))),
                          tuple(frozenset() for _ in order), tuple(map(str, order)),
                          np.full(len(order), -1))
        return reach_min(chain, target[order])

    assert at(0) == 1.0 and at(n - 1) == 1.0
    assert at(n + 1) == 0.0
    assert 0.5 - 1e-12 <= at(n + 2) <= 0.5

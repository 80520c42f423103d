"""A maximum's prob-0 state whose row stores a zero-probability entry to the goal, on
the analysis's quotient levels (-1 outside the quotient): the certificate of the
optimum still closes and holds the exact optimum.

The graph analysis reads no stored zero, so such a state is prob-0 (no level: it is
not in the quotient), but the Bellman check reads the row as stored: at 0 its rounded
sum is above 0 and the stored goal entry lets the rule ask for it, so the state fails
and must be repaired (to the rounding's few ulps).  The sensed route's chain models
store such entries (a hypothesis of weight 0: ``test_sensing_tasks``'s mixed end
components).  The exact optimum is found apart: every deterministic memoryless policy's
chain solved in fractions, the best taken state by state.
"""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np
from conftest import build_mdp

from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.certify import certify

GOAL, DEAD = 4, 5
# 0: try (3/8 to the goal) or wait in the end component {1, 2}; 1 may leave it for the
# goal or the prob-0 state 3, whose one row stores the goal with probability 0
CHOICES = [
    [("try", {GOAL: 0.375, DEAD: 0.625}), ("wait", {1: 1.0})],
    [("stay", {2: 1.0}), ("exit", {GOAL: 0.5, 3: 0.5})],
    [("back", {1: 1.0})],
    [("fall", {GOAL: 0.0, DEAD: 1.0})],
    [],
    [],
]


def _exact() -> list[Fraction]:
    """Per state the best, over the deterministic memoryless policies, of the exact
    probability of reaching the goal: each policy's chain iterated from 0 in fractions
    until it stops moving (its graph is acyclic apart from the end component's
    cycle, whose states never reach the goal unless one leaves it: the iterates are
    then exact after a few steps; checked by asking a fixed point)."""
    p = [[{t: Fraction(q) for t, q in d.items()} for _, d in c] for c in CHOICES]
    best = [Fraction(0)] * len(p)
    for policy in itertools.product(*(range(len(c)) or [0] for c in p)):
        x = [Fraction(int(s == GOAL)) for s in range(len(p))]
        for _ in range(4 * len(p)):
            y = [x[s] if not p[s] else sum((q * x[t] for t, q in p[s][a].items()),
                                           Fraction(0))
                 for s, a in enumerate(policy)]
            if y == x:
                break
            x = y
        assert y == x
        best = [max(b, v) for b, v in zip(best, x, strict=True)]
    return best


def test_prob0_state_storing_a_zero_entry_is_repaired_on_quotient_levels() -> None:
    mdp = build_mdp(CHOICES, target=[GOAL], sink=[DEAD])
    assert np.count_nonzero(mdp.matrix.data == 0.0) == 1  # the stored zero kept
    exact = _exact()
    assert exact[0] == Fraction(1, 2)  # waiting, then exit: 1/2 beats trying's 3/8
    q, _ = analyse(mdp, mdp.target)
    comp, level = (np.asarray(a) for a in q.layers)
    assert level[comp[3]] == -1  # the case: the state 3 has no level
    policy = np.array([1, 3, 4, 5, -1, -1], dtype=np.int64)  # wait, exit, back, fall
    cert = certify(mdp, mdp.target, policy, zero=q.qualitative.zero,
                   mec_of=q.mecs.mec_of, layers=q.layers, precision=1e-6)
    assert cert.certified, cert.checks
    assert Fraction(cert.lower) <= exact[0] <= Fraction(cert.upper)
    assert cert.upper - cert.lower <= 1e-6

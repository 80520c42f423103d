"""The certificate's heap trim before its last check (``certify(trim=True)``, asked by the
plain route from a million transitions): the same certificate, to the bit, and the
trim made once, only where asked for."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import MDP
from mitld_lp.solvers import certify as certify_module
from mitld_lp.solvers.certify import certify


def _mdp() -> tuple[MDP, np.ndarray, np.ndarray]:
    # s0 -a-> s1 (1/4) or s0 (3/4); s0 -b-> s1 (1/10) or s2 (9/10); s1 target, s2 sink:
    # Pmax = 1 (a, looped until s1), reached by policy a; Pmin = 1/10 (b)
    rows = np.array([[0.75, 0.25, 0.0], [0.0, 0.1, 0.9], [0, 1, 0], [0, 0, 1]])
    target, sink = np.array([False, True, False]), np.array([False, False, True])
    mdp = MDP(matrix=sp.csr_array(rows), row_groups=np.array([0, 2, 3, 4], dtype=np.int64),
              choice_actions=np.array([0, 1, 0, 0], dtype=np.int32), action_names=("a", "b"),
              initial=0, target=target, sink=sink, truncated=np.zeros(3, dtype=bool),
              states=[0, 1, 2])
    return mdp, target, sink


@pytest.mark.parametrize("policy, exact", [(0, Fraction(1)), (1, Fraction(1, 10))])
def test_trim_keeps_the_certificate_and_is_made_once(monkeypatch, policy, exact) -> None:
    mdp, target, sink = _mdp()
    calls = []
    monkeypatch.setattr(certify_module, "release_free_memory", lambda: calls.append(1))
    chosen = np.array([policy, -1, -1])
    kept = certify(mdp, target, chosen, zero=sink, sides=("lower",))
    assert calls == []
    trimmed = certify(mdp, target, chosen, zero=sink, sides=("lower",), trim=True)
    assert calls == [1]
    assert kept.lower == trimmed.lower and np.array_equal(kept.values, trimmed.values)
    # the policy's value by hand: a loops at 3/4 until s1 (1), b reaches s1 at 1/10
    assert Fraction(kept.lower) <= exact
    assert exact - Fraction(kept.lower) < Fraction(1, 10**9)

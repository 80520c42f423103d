"""The early jump's cost model (mitld_lp.solvers.jump_cost): the decision is a function of
the block alone, read from no clock, so a slow machine decides and computes the same
bits as a fast one; the rule jumps a block whose LU does not fill and refuses one whose
LU fills; the brackets hold Storm's exact values either way.

Expected values from independent routes: the LU's multiplies of a tree (no fill: one a
non-root state) and of a complete graph (``sum k^2``) by hand; the depth of a path and
of a grid by hand; Storm's exact engine on the gambler's ruin of
tests/test_sweep_forecast.py written in PRISM."""

from __future__ import annotations

import logging
import time
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from storm_exact import storm_rational
from test_consensus_62 import _block, _random
from test_sweep_forecast import PRISM as RUIN
from test_sweep_forecast import _ruin

from mitld_lp import defaults
from mitld_lp.solvers import Status, interval_iteration, iteration, jump_cost
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.topological import Block


def _tree(n: int) -> sp.csr_array:
    """A binary tree's pattern, both ways (state ``s``'s parent ``(s - 1) // 2``)."""
    child = np.arange(1, n)
    parent = (child - 1) // 2
    rows = np.concatenate([child, parent])
    cols = np.concatenate([parent, child])
    return sp.csr_array((np.ones(rows.size), (rows, cols)), shape=(n, n))


def _tree_block(n: int) -> Block:
    """Two choices a state, each to its parent, its children and its grandparent (or
    itself where there is none): a tree with chords inside triangles, whose LU does not
    fill in a minimum-degree order."""
    def near(s: int, k: int) -> list[int]:
        up = (s - 1) // 2 if s else 0
        kids = [c if c < n else up for c in (2 * s + 1, 2 * s + 2)]
        far = (up - 1) // 2 if up else 0
        return [up, *kids, far] if k == 0 else [*kids, up, far]
    return _block(n, near)


def test_the_lu_multiplies_of_a_tree_and_of_a_complete_graph() -> None:
    # a tree in a minimum-degree order: each state but the last leaves with one
    # neighbour left (its parent): one multiply each, no fill
    assert jump_cost.lu_flops(_tree(1000)) == 999.0
    # a complete graph of m states: the k-th pivot from the end has k entries below
    # and k right of it: sum k^2 for k < m
    m = 40
    full = sp.csr_array(np.ones((m, m)) - np.eye(m))
    assert jump_cost.lu_flops(full) == sum(k * k for k in range(m))


def test_the_depth_of_a_path_and_of_a_grid() -> None:
    n = 50
    step = sp.csr_array((np.ones(n - 1), (np.arange(n - 1), np.arange(1, n))), shape=(n, n))
    path = sp.csr_array(step + step.T)  # _depth reads a graph without directions
    assert jump_cost._depth(path)[0] == n - 1  # from state 0 to the far end and back
    # a block of two components, the short path first: the longer one's depth counts
    two = sp.block_diag([path[:10, :10], path], format="csr")
    assert jump_cost._depth(two)[0] == n - 1
    side = 12  # a grid of side x side: the corners are 2 (side - 1) apart
    g = sp.kron(sp.eye_array(side), sp.diags_array([1.0, 1.0], offsets=[-1, 1],
                                                    shape=(side, side)))
    g = sp.csr_array(g + sp.kron(sp.diags_array([1.0, 1.0], offsets=[-1, 1],
                                                shape=(side, side)), sp.eye_array(side)))
    assert jump_cost._depth(g)[0] == 2 * (side - 1)


def test_the_state_graph_is_every_choice_s_moves_both_ways() -> None:
    block = _random(40)
    want = np.zeros((40, 40), dtype=bool)
    for s in range(40):  # by hand: each choice of s, each of its entries
        for c in range(int(block.starts[s]), int(block.groups[s + 1])):
            for t in block.inner.indices[block.inner.indptr[c]:block.inner.indptr[c + 1]]:
                want[s, t] = want[t, s] = True
    assert np.array_equal(jump_cost._state_graph(block).toarray() != 0, want)


def test_the_rule_jumps_a_block_whose_lu_does_not_fill_and_refuses_one_that_does() -> None:
    """Two blocks of 1,500 states, two choices a state, four successors a choice: the
    random one's LU fills (its multiplies thousands of times the tree's), so its jump
    costs more than the 968 sweeps the early look can save; the tree's does not, and a
    few rounds cost some hundred sweeps."""
    saved = 968.0  # the sweeps left to the limit of 1,000 after the early look at 32
    random_block, tree_block = _random(1500), _tree_block(1500)
    fills = jump_cost.cost(random_block, random_block.starts)
    flat = jump_cost.cost(tree_block, tree_block.starts)
    assert fills.flops > 1000 * flat.flops
    assert flat.flops < 2 * 1500  # no fill: about one multiply a state
    assert not jump_cost.worth(fills, saved)
    assert jump_cost.worth(flat, saved)
    # the allowance is what the saved sweeps pay for, in rounds
    assert flat.allowance(saved) == pytest.approx(saved * flat.sweep / flat.round)
    assert fills.allowance(saved) < 1.0


class _SlowClock:
    """A clock that runs a thousand seconds between two readings (a loaded machine)."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        self.now += 1000.0
        return self.now


def test_the_decision_is_the_block_s_whatever_the_clock(monkeypatch) -> None:
    block = _random(600)
    before = jump_cost.cost(block, block.starts)
    monkeypatch.setattr(time, "process_time", _SlowClock())
    monkeypatch.setattr(time, "perf_counter", _SlowClock())
    after = jump_cost.cost(block, block.starts)
    assert after == before


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_the_ruin_gives_the_same_bits_on_a_slow_clock_and_holds_storms_value(
        tmp_path: Path, sense: Sense, monkeypatch, caplog) -> None:
    """The ruin's block swept by the compiled kernel, read at 32 sweeps and jumped
    there (its 39 states cost a few rounds of a few sweeps each): the same decision,
    sweeps and bracket to the bit with the process and wall clocks running a thousand
    seconds a reading; the bracket holds Storm's exact value."""
    pytest.importorskip("stormpy")
    pytest.importorskip("numba")
    path = tmp_path / "ruin.prism"
    path.write_text(RUIN, encoding="utf-8")
    exact = storm_rational(path, f'P{sense.value}=? [F "goal"]')
    mdp = _ruin()
    runs = []
    for slow in (False, True):
        if slow:
            monkeypatch.setattr(time, "process_time", _SlowClock())
            monkeypatch.setattr(time, "perf_counter", _SlowClock())
        caplog.clear()
        with caplog.at_level(logging.DEBUG, logger="mitld_lp.solvers.iteration"):
            r = interval_iteration(mdp, mdp.target, sense=sense, progress=False,
                                   compiled=True)
        decisions = [m for m in caplog.messages if m.startswith("early jump")]
        runs.append((r, decisions))
    (fast, said), (slow_r, said_slow) = runs
    assert said == said_slow and said, said
    assert fast.iterations == slow_r.iterations == iteration._EARLY[0]
    assert np.array_equal(fast.lower, slow_r.lower)
    assert np.array_equal(fast.upper, slow_r.upper)
    assert fast.status is Status.OPTIMAL, fast.message
    lo, hi = Fraction(fast.value_lower), Fraction(fast.value_upper)
    # rounded to nearest, the lower bound may sit one rounding above the exact value
    # (tests/test_rare_events.py), the upper one not below it
    assert lo <= exact * (1 + Fraction(1, 2**50)) and exact <= hi, (lo, exact, hi)
    assert hi - lo <= Fraction(defaults.TOL)


"""The single-state levels built once a quotient (solvers.shared_levels).

* the shared levels are, array for array, those built afresh, on random acyclic and
  cyclic MDPs; the iteration walking them without its skip set and putting the
  skipped states back gives the bounds of the walk with the skip, bit for bit, and the
  iteration's result is the one of its own levels with the skip;
* the kept levels go when their quotient goes, and the LP stage takes them;
* on a small deadline-like MDP with a near-tie, the certified bracket holds the value
  found by enumerating every deterministic policy in exact arithmetic.
"""

from __future__ import annotations

import gc
import itertools
from fractions import Fraction

import numpy as np
import pytest
from conftest import build_mdp
from test_level_runs import _mixed
from test_single_levels import layered_mdp

from mitld_lp.solvers import iteration, shared_levels
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.topological import SingleLevels
from mitld_lp.util.traversal import breadth_first_order

SLOTS = [s for s in SingleLevels.__slots__ if s not in ("sense", "kernels", "positive")]


def _quotient(mdp, sense: Sense):
    q, _ = analyse(mdp, mdp.target, sense=sense)
    return q


def _random(kind: str, seed: int):
    return layered_mdp(seed, depth=30)[0] if kind == "acyclic" else _mixed(seed, depth=30)


def _skip(q) -> np.ndarray:
    """The iteration's skip set: what the initial state cannot reach."""
    from mitld_lp.solvers.topological import state_graph

    skip = np.ones(q.n_states, dtype=bool)
    skip[np.asarray(breadth_first_order(state_graph(q), q.initial))] = False
    return skip


def _equal(a: SingleLevels, b: SingleLevels) -> None:
    for name in SLOTS:
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and np.array_equal(x, y), name
        else:
            assert x == y, name
    assert (a.sense, a.kernels, a.positive) == (b.sense, b.kernels, b.positive)


@pytest.mark.parametrize("kind", ["acyclic", "cyclic"])
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_shared_levels_are_those_built_afresh(kind: str, seed: int, sense: Sense) -> None:
    q = _quotient(_random(kind, seed), sense)
    shared = shared_levels.shared_levels(q, q.order)
    assert shared_levels.shared_levels(q, q.order) is shared  # built once
    _equal(shared, SingleLevels(q, q.order))
    # a skip set that leaves no single state out builds the same arrays
    _equal(shared, SingleLevels(q, q.order, np.zeros(q.n_states, dtype=bool)))


@pytest.mark.parametrize("kind", ["acyclic", "cyclic"])
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_the_walk_without_the_skip_set_then_put_back_is_the_walk_with_it(
        kind: str, seed: int, sense: Sense) -> None:
    q = _quotient(_random(kind, seed), sense)
    skip = _skip(q)
    b = q.order
    restricted = SingleLevels(q, b, skip)
    shared = shared_levels.shared_levels(q, b)
    assert restricted.states.size < shared.states.size  # the skip set leaves some out
    rewards = np.repeat(q.to_target[:, None], 2, axis=1)
    start = np.zeros((q.n_states, 2))
    start[:, 1] = np.where(q.zero, 0.0, 1.0)
    want, got = start.copy(), start.copy()
    # the single states only: the levels below the first block of each
    stop = (int(b.level[b.size > 1].min()) if (b.size > 1).any() else b.n_levels)
    restricted.solve(0, stop, rewards, want)
    held = shared.states[skip[shared.states]]
    kept = got[held]
    shared.solve(0, stop, rewards, got)
    got[held] = kept
    assert np.array_equal(want.view(np.int64), got.view(np.int64))


@pytest.mark.parametrize("kind", ["acyclic", "cyclic"])
@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_the_iteration_with_shared_levels_gives_the_old_bounds(
        monkeypatch: pytest.MonkeyPatch, kind: str, seed: int, sense: Sense) -> None:
    mdp = _random(kind, seed)
    shared = interval_iteration(mdp, mdp.target, sense=sense, progress=False)
    monkeypatch.setattr(iteration, "RUNS_MIN_LEVELS", 10**9)  # its own, with the skip
    own = interval_iteration(mdp, mdp.target, sense=sense, progress=False)
    for name in ("lower", "upper", "policy"):
        a, b = getattr(shared, name), getattr(own, name)
        assert np.array_equal(np.asarray(a).view(np.int64), np.asarray(b).view(np.int64))
    assert shared.message == own.message


def test_the_kept_levels_go_with_their_quotient() -> None:
    q = _quotient(layered_mdp(0, depth=30)[0], Sense.MAX)
    shared_levels.shared_levels(q, q.order)
    key = id(q.matrix)
    assert key in shared_levels._KEPT
    del q
    gc.collect()
    assert key not in shared_levels._KEPT


def test_the_lp_stage_takes_the_levels_it_is_the_last_to_use() -> None:
    q = _quotient(layered_mdp(1, depth=30)[0], Sense.MAX)
    first = shared_levels.shared_levels(q, q.order)
    assert shared_levels.shared_levels(q, q.order, last=True) is first
    assert id(q.matrix) not in shared_levels._KEPT  # not kept past the LP
    again = shared_levels.shared_levels(q, q.order, last=True)  # built anew, not kept
    assert again is not first and id(q.matrix) not in shared_levels._KEPT
    _equal(first, again)


def _near_tie(depth: int = 20):
    """A chain of ``depth`` layers; layer ``k``'s state ``2k`` has two choices: ``A``
    to the goal with probability ``x`` (the rest to the sink) and ``B`` to the goal with
    ``y < x`` and to a coin state of value exactly 1/2 with ``z``, ``x`` one ulp below
    ``B``'s float score: tied within 1e-12, ``A`` preferred (the larger one-step
    probability) though it scores below the top.  Each also moves on to the next
    layer's state with a small probability; ``2k + 1`` (the coin) is unreachable from
    the initial state but by the chain."""
    rows = []
    goal, sink = 2 * depth, 2 * depth + 1
    for k in range(depth):
        nxt = 2 * (k + 1) if k + 1 < depth else sink
        y, z = 0.35, 0.2
        score_b = y + z * 0.5
        x = float(np.nextafter(score_b, 0.0))
        rows.append([("A", _row([(goal, x * 0.9), (nxt, 0.1)], sink)),
                     ("B", _row([(goal, y * 0.9), (2 * k + 1, z * 0.9), (nxt, 0.1)], sink))])
        rows.append([("coin", {goal: 0.5, sink: 0.5})])
    rows += [[], []]
    return build_mdp(rows, target=[goal], sink=[sink])


def _row(moves, sink: int) -> dict[int, float]:
    """``moves`` as a distribution, what they leave added to ``sink``."""
    row: dict[int, float] = {}
    for t, p in moves:
        row[t] = row.get(t, 0.0) + p
    row[sink] = row.get(sink, 0.0) + 1.0 - sum(p for _, p in moves)
    return row


def _exact_optimum(mdp, sense: Sense) -> Fraction:
    """The optimum at the initial state over every deterministic policy, each policy's
    chain solved backward in exact arithmetic (the MDP is acyclic but for self-loops:
    states in decreasing order)."""
    n = mdp.n_states
    target = np.asarray(mdp.target, dtype=bool)
    a = mdp.matrix.tocsr()
    groups = [range(int(mdp.row_groups[s]), int(mdp.row_groups[s + 1])) for s in range(n)]
    free = [s for s in range(n) if not target[s] and len(groups[s]) > 1]
    best = None
    for pick in itertools.product(*(groups[s] for s in free)):
        chosen = {s: groups[s][0] for s in range(n)}
        chosen.update(dict(zip(free, pick, strict=True)))
        v: dict[int, Fraction] = {}
        for s in range(n - 1, -1, -1):
            if target[s]:
                v[s] = Fraction(1)
                continue
            c = chosen[s]
            row = a[[c]]
            stay, gain = Fraction(0), Fraction(0)
            for t, p in zip(row.indices.tolist(), row.data.tolist(), strict=True):
                if t == s:
                    stay += Fraction(p)
                else:
                    gain += Fraction(p) * v[t]
            v[s] = gain / (1 - stay) if stay < 1 else Fraction(0)
        val = v[0]
        best = val if best is None else (max(best, val) if sense is Sense.MAX
                                         else min(best, val))
    return best


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_a_small_deadline_like_mdp_brackets_the_brute_force_value(sense: Sense) -> None:
    from mitld_lp.solvers.certify import certify
    from mitld_lp.solvers.lp import solve_lp

    mdp = _near_tie(depth=6)  # 2**6 deterministic policies
    want = _exact_optimum(mdp, sense)
    it = interval_iteration(mdp, mdp.target, sense=sense, progress=False)
    assert Fraction(it.value_lower) - Fraction(2.0 ** -50) <= want
    assert want <= Fraction(it.value_upper) + Fraction(2.0 ** -50)
    lp = solve_lp(mdp, mdp.target, sense=sense, bounds=(it.lower, it.upper))
    q, _ = analyse(mdp, mdp.target, sense=sense)
    low = sense is Sense.MIN
    cert = certify(mdp, mdp.target, lp.policy, sense=str(sense), zero=q.qualitative.zero,
                   one=q.qualitative.one if low else None,
                   mec_of=None if low else q.mecs.mec_of, layers=q.layers,
                   fallback_lower=it.lower, fallback_upper=it.upper, precision=1e-6)
    assert cert.certified, cert.checks
    assert Fraction(cert.lower) <= want <= Fraction(cert.upper)

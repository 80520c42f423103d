"""The single-state levels built once a quotient (solvers.shared_levels) and the LP's
values walk checking the iteration's bounds first (level_batches.values' ``guess``).

* the shared levels are, array for array, those built afresh, on random acyclic and
  cyclic MDPs; the iteration walking them without its skip set and putting the
  skipped states back gives the bounds of the walk with the skip, bit for bit;
* the values walk with a guess (right, wrong by one ulp, or the iteration's bound
  where a near-tie's pick scores below the top) writes what the walk without one
  writes, bit for bit;
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
from test_single_levels import _layered

from mitld_lp.solvers import iteration, level_batches, shared_levels
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
    return _layered(seed, depth=30)[0] if kind == "acyclic" else _mixed(seed, depth=30)


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
    q = _quotient(_layered(0, depth=30)[0], Sense.MAX)
    shared_levels.shared_levels(q, q.order)
    key = id(q.matrix)
    assert key in shared_levels._KEPT
    del q
    gc.collect()
    assert key not in shared_levels._KEPT


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


def _walk_values(q, sl, guess):
    values = np.zeros(q.n_states)
    choice = np.full(q.n_states, -1, dtype=np.int64)
    weights = np.zeros(q.n_choices)
    sl.values(0, q.order.n_levels, q.to_target, q.zero, values, choice, weights, guess)
    return values, choice, weights


def _same_walk(a, b) -> None:
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x.view(np.int64), y.view(np.int64))


@pytest.mark.parametrize("case", ["acyclic", "near_tie"])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_the_values_walk_with_a_guess_writes_what_the_walk_without_one_writes(
        monkeypatch: pytest.MonkeyPatch, case: str, sense: Sense) -> None:
    mdp = _layered(3, depth=40)[0] if case == "acyclic" else _near_tie()
    q = _quotient(mdp, sense)
    if (q.order.size > 1).any():
        pytest.skip("not single states only")
    sl = SingleLevels(q, q.order, compiled=False)
    assert sl.ptr is not None  # the compiled CSR product's path (where the guess is read)
    monkeypatch.setattr(level_batches, "GROUP_ENTRIES", 16)  # several groups
    want = _walk_values(q, sl, None)
    seen = []
    checked = level_batches._checked

    def counted(*args):
        k = checked(*args)
        seen.append((k, len(args[1])))
        return k

    monkeypatch.setattr(level_batches, "_checked", counted)
    # the walk's own values: every level taken from the guess
    _same_walk(want, _walk_values(q, sl, want[0].copy()))
    assert all(k == n for k, n in seen)
    # one ulp off at a state half-way up: the levels from there on are walked
    wrong = want[0].copy()
    s = int(sl.states[sl.states.size // 2])
    wrong[s] = np.nextafter(wrong[s], 2.0)
    seen.clear()
    _same_walk(want, _walk_values(q, sl, wrong))
    assert any(k < n for k, n in seen)
    # the iteration's bound (the top of each state's scores)
    it = interval_iteration(mdp, mdp.target, sense=sense, gap="max", progress=False)
    kept = np.asarray(q.state_map) >= 0
    bound = np.zeros(q.n_states)
    bound[np.asarray(q.state_map)[kept]] = np.asarray(it.lower)[kept]
    _same_walk(want, _walk_values(q, sl, bound))


def test_a_near_tie_makes_the_pick_score_below_the_top() -> None:
    """The near-tie case does what it is there for: the walk's value at a state with
    the tie is the preferred choice's, one ulp below the top its bound takes."""
    mdp = _near_tie()
    q = _quotient(mdp, Sense.MAX)
    sl = SingleLevels(q, q.order, compiled=False)
    values, _, _ = _walk_values(q, sl, None)
    bounds = np.zeros((q.n_states, 1))
    sl.solve(0, q.order.n_levels, q.to_target[:, None], bounds)
    assert (values < bounds[:, 0]).any()
    # and with the top as the guess, the walk's answer all the same
    _same_walk(_walk_values(q, sl, None), _walk_values(q, sl, bounds[:, 0].copy()))


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

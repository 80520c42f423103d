"""The solve stage's memory peak (branch mem-peak) against routes written otherwise.

* the layers kept in the index type (int32) give the int64 layers' certificate to the
  bit, and are the same numbers;
* the certificate's base vector and levels made per candidate, its batches forced
  small: the same certificate to the bit;
* the chain's values (the acting rows freed early) against a dense solve (numpy);
* the block walk's progress counts (a read-only view of one int64 per run) add up to
  the states the walk solves, counted from the quotient.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import build_mdp

from mitld_lp.solvers import analysis, certify_chain, lp_blocks, rounding
from mitld_lp.solvers import certify as C
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp


def _layered_mdp(seed: int, levels: int = 24, width: int = 3):
    """A deadline-like MDP: ``levels`` levels of ``width`` states, each choice moving
    down one or two levels (or to the goal / the dead end), some states with a
    self-loop and some pairs of states on one level in a cycle; more levels than
    ``RUNS_MIN_LEVELS``, so the LP walks its single states a run of levels at a time."""
    rng = np.random.default_rng(seed)
    n = levels * width
    goal, dead = n, n + 1
    states = []
    for s in range(n):
        lv = s // width
        mine = []
        for a in range(int(rng.integers(1, 4))):
            below = [t for t in range((lv - 2) * width, lv * width) if t >= 0]
            pool = below + [goal, dead] if below else [goal, dead]
            succ = set(rng.choice(pool, size=min(3, len(pool)), replace=False).tolist())
            if rng.random() < 0.2:
                succ.add(s)  # a self-loop (divided out by the walks)
            if rng.random() < 0.15 and s % width + 1 < width:
                succ.add(s + 1)  # a cycle with its neighbour on the level
                if a == 0:
                    succ.add(goal)
            succ = sorted(succ)
            w = rng.integers(1, 9, size=len(succ)).astype(float)
            row = {int(t): float(x) for t, x in zip(succ, w / w.sum(), strict=True)}
            row[succ[-1]] += 1.0 - sum(row.values())
            mine.append((f"a{a}", row))
        states.append(mine)
    # the neighbours' cycles: each state of a level may also move back to the first
    for s in range(n):
        if s % width and rng.random() < 0.3:
            row = {s - s % width: 0.5, goal: 0.25, dead: 0.25}
            states[s].append(("back", row))
    states += [[], []]
    return build_mdp(states, initial=n - 1, target=[goal], sink=[dead])


@pytest.fixture(scope="module")
def mdps():
    return [_layered_mdp(seed) for seed in range(3)]


def _bits(a) -> np.ndarray:
    a = np.asarray(a)
    return a.view(np.int64) if a.dtype == np.float64 else a


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and np.array_equal(_bits(a), _bits(b))


def _solved(mdp, sense: Sense):
    """The analysis, the iteration, the LP (everywhere) and the certificate of ``mdp``
    as the plain route chains them (its layers, zero and one sets, fallbacks)."""
    q = analysis.analyse(mdp, mdp.target, sense=sense)[0]
    it = interval_iteration(mdp, mdp.target, quotient=q, sense=sense)
    lp = solve_lp(mdp, mdp.target, quotient=q, sense=sense, everywhere=True,
                  bounds=(it.lower, it.upper))
    d = q.qualitative
    minimum = sense is Sense.MIN
    cert = C.certify(mdp, np.asarray(q.target), lp.policy, sense=str(sense), zero=d.zero,
                     one=d.one if minimum else None,
                     mec_of=None if minimum else q.mecs.mec_of, layers=q.layers,
                     fallback_lower=it.lower, fallback_upper=it.upper, precision=1e-6)
    return q, it, lp, cert


def _answers(q, it, lp, cert) -> list:
    return [it.lower, it.upper, lp.values, lp.policy, lp.occupancy, lp.randomized,
            cert.values, np.array([cert.lower, cert.upper]),
            np.array([c.passed for c in cert.checks])]


def test_int32_layers_give_the_int64_layers_certificate_to_the_bit(mdps, monkeypatch
                                                                    ) -> None:
    for mdp in mdps:
        for sense in (Sense.MAX, Sense.MIN):
            narrow = _solved(mdp, sense)
            assert narrow[0].layers[0].dtype == np.int32
            assert narrow[0].layers[1].dtype == np.int32
            with monkeypatch.context() as m:
                m.setattr(analysis, "index_dtype", lambda n: np.int64)
                wide = _solved(mdp, sense)
            assert wide[0].layers[0].dtype == np.int64
            for a, b in zip(narrow[0].layers, wide[0].layers, strict=True):
                assert np.array_equal(a, b)  # the same numbers
            assert narrow[3].certified
            assert all(_same(a, b) for a, b in zip(_answers(*narrow), _answers(*wide),
                                                   strict=True))


def test_small_batches_and_a_forced_repair_give_the_same_certificate(mdps, monkeypatch
                                                                     ) -> None:
    """The Bellman checks and the support reads a few rows at a time give the
    certificate of the whole arrays; a candidate pulled off the fixed point (so that
    the repair, with its levels made on demand, runs) is certified as before."""
    for mdp in mdps:
        q, it, lp, cert = _solved(mdp, Sense.MAX)
        with monkeypatch.context() as m:
            m.setattr(C, "BATCH", 3)
            m.setattr(rounding, "BATCH", 2)
            small = _solved(mdp, Sense.MAX)[3]
        assert all(_same(a, b) for a, b in zip(_answers(q, it, lp, cert),
                                               _answers(q, it, lp, small), strict=True))
        # the policy's chain values lowered: the lower candidate fails at first; the
        # repair (made only then) must close it, the bound still below the iteration's
        # upper bound of the optimum
        ch = C.chain(mdp, np.asarray(q.target), lp.policy,
                     C.rounding(mdp.matrix), q.layers)
        off = certify_chain.Chain(*(np.asarray(f) for f in (
            ch.values * 0.5, ch.slack, ch.solved, ch.sure, ch.never, ch.policy,
            ch.target)))
        side = C.optimum_upper(mdp, off, C.rounding(mdp.matrix), zero=q.qualitative.zero,
                               layers=q.layers, mec_of=q.mecs.mec_of,
                               fallback=it.upper)
        assert side.check.passed and "states repaired" in side.check.detail
        assert side.value >= lp.value - 1e-12  # an upper bound of the optimum


def test_the_chain_values_solve_the_policys_equations(mdps) -> None:
    for mdp in mdps:
        q, _, lp, _ = _solved(mdp, Sense.MAX)
        ch = C.chain(mdp, np.asarray(q.target), lp.policy, C.rounding(mdp.matrix),
                     q.layers)
        # the policy's chain, dense: v = P_pi v on the acting states, 1 on the target
        n = mdp.n_states
        p = mdp.matrix.toarray()
        target = np.asarray(q.target)
        rows = np.zeros((n, n))
        acting = (lp.policy >= 0) & ~target
        rows[acting] = p[lp.policy[acting]]
        a = np.eye(n) - rows
        b = target.astype(float)
        live = acting | target
        v = np.zeros(n)
        # states that cannot reach the target have value 0: solve on the rest
        reach = target.copy()
        for _ in range(n):
            reach |= acting & ((rows > 0) @ reach > 0)
        keep = np.flatnonzero(live & reach)
        v[keep] = np.linalg.solve(a[np.ix_(keep, keep)], b[keep])
        assert np.allclose(ch.values, v, atol=1e-12)


def test_the_block_walks_progress_counts_the_states_it_solves(mdps, monkeypatch) -> None:
    seen: list[tuple[int, int]] = []
    inner = lp_blocks.tracked

    def counting(items, shown, size=None, **options):
        total, done = options.get("total"), 0
        for item in inner(items, shown, size, **options):
            done += int(size(item))
            yield item
        seen.append((done, total))

    monkeypatch.setattr(lp_blocks, "tracked", counting)
    for mdp in mdps:
        q = analysis.analyse(mdp, mdp.target)[0]
        # every state of the quotient but those known to be 0
        want = q.n_states - int(np.count_nonzero(q.zero))
        seen.clear()
        solve_lp(mdp, mdp.target, quotient=q, everywhere=True)
        assert seen == [(want, want)]

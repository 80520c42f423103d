"""The solvers' memory-lean arrays (branch mem-arrays) against routes written otherwise.

* ``index_dtype``: int32 up to 2**31 - 1, int64 past it (never a wrapped index), a
  negative size refused;
* ``spread``: a per-state figure repeated over each state's choices, against a loop;
* the LP's occupancy and randomised policy built from the quotient's choices alone, a
  slice of states at a time, against the dense per-choice occupancy divided state by
  state in a loop;
* the policy's occupancy (``policy_flow``, spread in place) against a dense linear
  solve of its flow equations (numpy);
* ``Quotient.lift`` and ``lift_policy`` (one gather) against loops over the states;
* the quotient's int32 state map, choice origins and end-component ids: the whole LP
  and iteration answers the same to the bit as with every index forced to int64.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import build_mdp

from mitld_lp.solvers import analysis
from mitld_lp.solvers import lp as lp_mod
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.quotient import lift_policy, reduce
from mitld_lp.util.arrays import index_dtype, spread


def _random_mdp(seed: int, n: int = 40):
    """Random choices among ``n`` states, some moving only among a few neighbours (end
    components), the goal ``n`` and a dead end ``n + 1``."""
    rng = np.random.default_rng(seed)
    goal, dead = n, n + 1
    states = []
    for s in range(n):
        mine = []
        for a in range(int(rng.integers(1, 4))):
            if rng.random() < 0.3:  # stays among s and its neighbours: cycles
                succ = sorted({s, (s + 1) % n, (s + 2) % n})
            else:
                succ = sorted(set(rng.choice(n + 2, size=3).tolist()))
            w = rng.integers(1, 9, size=len(succ)).astype(float)
            p = w / w.sum()
            row = {int(t): float(x) for t, x in zip(succ, p, strict=True)}
            last = succ[-1]
            row[last] += 1.0 - sum(row.values())
            mine.append((f"a{a}", row))
        states.append(mine)
    states += [[], []]
    return build_mdp(states, target=[goal], sink=[dead])


@pytest.fixture(scope="module")
def mdps():
    out = [_random_mdp(seed) for seed in range(4)]
    assert any(reduce(m, m.target).mecs.n_mecs for m in out)  # collapsed ones too
    return out


def test_index_dtype_is_int32_up_to_its_largest_and_int64_past_it() -> None:
    top = np.iinfo(np.int32).max
    assert index_dtype(0) is np.int32
    assert index_dtype(top) is np.int32
    assert index_dtype(top + 1) is np.int64  # an index of 2**31 would wrap in int32
    assert index_dtype(2**40) is np.int64
    with pytest.raises(ValueError, match="negative"):
        index_dtype(-1)


def test_spread_repeats_each_states_figure_over_its_choices() -> None:
    groups = np.array([0, 2, 2, 5, 6, 9])  # a state with no choice among them
    per_state = np.array([0.5, 7.0, -1.0, 3.0, 2.5])
    want = [per_state[s] for s in range(5) for _ in range(groups[s], groups[s + 1])]
    assert np.array_equal(spread(per_state, groups, 0, 5), want)
    assert np.array_equal(spread(per_state, groups, 1, 4),
                          want[groups[1]:groups[4]])


def _dense_randomized(mdp, origin, y, policy, threshold):
    """The dense route: every choice's occupancy, then each state's share in a loop."""
    groups = np.asarray(mdp.row_groups)
    occupancy = [0.0] * mdp.n_choices
    for c, v in zip(origin.tolist(), y.tolist(), strict=True):
        occupancy[c] = v
    out = []
    for s in range(mdp.n_states):
        ys = occupancy[groups[s]:groups[s + 1]]
        flow = 0.0
        for v in ys:  # in the product's order, from +0.0
            flow += v
        for k, c in enumerate(range(groups[s], groups[s + 1])):
            out.append(ys[k] / flow if flow > threshold else
                       (1.0 if policy[s] == c else 0.0))
    return np.array(occupancy), np.array(out)


def test_the_randomised_policy_from_the_quotients_choices_is_the_dense_routes(
        mdps, monkeypatch) -> None:
    monkeypatch.setattr(lp_mod, "SLICE_STATES", 7)  # several slices on a small MDP
    rng = np.random.default_rng(5)
    for mdp in mdps:
        groups = np.asarray(mdp.row_groups)
        # a subset of the choices, increasing within each state, states shuffled
        order = rng.permutation(mdp.n_states)
        origin = np.concatenate([np.arange(groups[s], groups[s + 1])[
            rng.random(groups[s + 1] - groups[s]) < 0.7] for s in order]).astype(np.int32)
        y = rng.random(origin.size) * (rng.random(origin.size) < 0.8)
        y[: origin.size // 5] *= 1e-9  # some states under the visit threshold
        policy = np.where(rng.random(mdp.n_states) < 0.5, groups[:-1], -1)
        tol = 1e-9
        occupancy, flow = lp_mod._occupancy(mdp, origin, y)
        randomized = lp_mod._randomized(mdp, occupancy, flow, policy, tol)
        want_occ, want = _dense_randomized(mdp, origin, y, policy,
                                           lp_mod._visit_threshold(tol))
        assert np.array_equal(occupancy, want_occ)
        assert np.array_equal(randomized, want)


def test_the_policy_occupancy_solves_its_flow_equations(mdps) -> None:
    for mdp in mdps:
        q = reduce(mdp, mdp.target)
        lp = solve_lp(mdp, mdp.target, quotient=q, everywhere=True)
        # the randomised policy's flow on the quotient, by a dense solve:
        # x = 1 + P_w^T x over the reduced states, y(c) = w(c) x(owner(c))
        groups = np.asarray(q.row_groups)
        owner = np.repeat(np.arange(q.n_states), np.diff(groups))
        y_red = lp.occupancy[q.choice_origin]
        flow = np.bincount(owner, weights=y_red, minlength=q.n_states)
        w = np.where(flow[owner] > 0, y_red / np.where(flow[owner] > 0, flow[owner], 1), 0)
        moves = q.matrix.toarray()
        p_w = np.zeros((q.n_states, q.n_states))
        for c in range(q.n_choices):
            p_w[owner[c]] += w[c] * moves[c]
        x = np.linalg.solve(np.eye(q.n_states) - p_w.T, np.ones(q.n_states))
        assert np.allclose(y_red, w * x[owner], rtol=1e-9, atol=1e-12)


def test_lift_and_lift_policy_are_the_loops_over_the_states(mdps) -> None:
    rng = np.random.default_rng(9)
    for mdp in mdps:
        q = reduce(mdp, mdp.target)
        values = rng.random(q.n_states)
        lifted = q.lift(values)
        for s in range(mdp.n_states):
            r = int(q.state_map[s])
            assert lifted[s] == (values[r] if r >= 0 else float(q.target[s]))
        choice = np.array([rng.integers(q.row_groups[r], q.row_groups[r + 1])
                           for r in range(q.n_states)], dtype=np.int64)
        policy = lift_policy(mdp, q, choice)
        for s in range(mdp.n_states):
            r = int(q.state_map[s])
            if r >= 0 and q.mecs.mec_of[s] < 0:
                assert policy[s] == q.choice_origin[choice[r]]
        assert policy.dtype == np.int64


def test_int32_indices_give_the_int64_answers_to_the_bit(mdps, monkeypatch) -> None:
    def answers(mdp, sense):
        q = analysis.analyse(mdp, mdp.target, sense=sense)[0]
        lp = solve_lp(mdp, mdp.target, quotient=q, sense=sense, everywhere=True)
        it = interval_iteration(mdp, mdp.target, quotient=q, sense=sense)
        return q, (q.state_map, q.choice_origin, q.mecs.mec_of, q.matrix.toarray(),
                   q.to_target, lp.values, lp.policy, lp.occupancy, lp.randomized,
                   it.lower, it.upper)

    for mdp in mdps:
        for sense in (Sense.MAX, Sense.MIN):
            narrow_q, narrow = answers(mdp, sense)
            assert narrow_q.state_map.dtype == np.int32
            assert narrow_q.choice_origin.dtype == np.int32
            with monkeypatch.context() as m:
                m.setattr(analysis, "index_dtype", lambda n: np.int64)
                wide_q, wide = answers(mdp, sense)
            assert wide_q.state_map.dtype == np.int64
            for a, b in zip(narrow, wide, strict=True):
                assert np.array_equal(a, b, equal_nan=True)
                if a.dtype.kind == "f":  # the same bits, not only equal
                    assert np.array_equal(a.view(np.int64), b.view(np.int64))


def test_the_stage_table_reports_the_peak_with_and_without_numbas_floor() -> None:
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import memory_stages

    rows = {"synthesize": dict(calls=1, peak=200.0, kept=150.0, without_numba=147.5)}
    loaded = memory_stages.text("x", dict(stages=rows, base_mb=1.0, numba_mb=50.0,
                                          transitions=2**20, top_where="", top=[]))
    # 50 MB over 2**20 transitions: 50 bytes a transition
    assert "50.0 MB" in loaded and "50.0 bytes a transition" in loaded
    assert "without that floor 147.5 bytes a transition, 200.0 with it" in loaded
    quiet = memory_stages.text("x", dict(stages=rows, base_mb=1.0, numba_mb=0,
                                         transitions=2**20, top_where="", top=[]))
    assert "numba not loaded" in quiet and "floor" not in quiet

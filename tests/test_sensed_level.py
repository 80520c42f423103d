"""The compiled parts of a level of the sensed build (:mod:`mitld_lp.sensing.group_kernels`:
the groupings by observation and by hypothesis, the least report counts, the sets'
hashes) and the states' records made on demand (:mod:`mitld_lp.sensing.states`),
against answers found another way: the rows grouped by sorting Python tuples, the least
counts and the hashes by plain loops, the whole product against the one-state-at-a-time
build of tests/test_sensing_build.py (an enumeration written apart, with dictionaries
of tuples) and against the NumPy lines, to the bit."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from test_sensing_build import CASES, assert_same, reference, with_sensors

from mitld_lp.automata.translate import to_dta
from mitld_lp.product import Absorbing
from mitld_lp.sensing import Sensor, rows
from mitld_lp.sensing.belief import InfoState, belief_product
from mitld_lp.sensing.states import InfoStates

numba = pytest.importorskip("numba")
gk = pytest.importorskip("mitld_lp.sensing.group_kernels")


def numbered(keys: list[tuple[int, ...]]) -> list[int]:
    """Each row's group: the rank of its key among the distinct keys, sorted."""
    rank = {k: i for i, k in enumerate(sorted(set(keys)))}
    return [rank[k] for k in keys]


def random_rows(rng: np.random.Generator, n: int, spread: int) -> tuple[np.ndarray, ...]:
    """``n`` rows: a non-decreasing choice, and three columns of ``spread`` values (many
    distinct words in a choice where ``spread`` is large: the sorting fallbacks)."""
    c = np.sort(rng.integers(0, max(n // 40, 1), n))
    return (c, *(rng.integers(-3, spread, n) for _ in range(3)))


@pytest.mark.parametrize("spread", [2, 6, 40])
@pytest.mark.parametrize("seed", [0, 1])
def test_groups_by_observation_and_hypothesis_as_sorted_tuples(seed: int, spread: int) -> None:
    rng = np.random.default_rng(seed)
    c, w, o, r = random_rows(rng, 3000, spread)
    with rows.running_kernels(True) as on:
        assert on
        found = gk.by_observation(rows.compiled_on(), c, w, o, r)
    assert found is not None
    obs, first, perm = found
    keys = list(zip(c.tolist(), w.tolist(), o.tolist(), r.tolist(), strict=True))
    assert obs.tolist() == numbered(keys)
    # one row of each group, in the groups' order; the permutation lists the rows group
    # after group
    assert [keys[i] for i in first.tolist()] == sorted(set(keys))
    assert sorted(perm.tolist()) == list(range(len(c)))
    assert np.all(np.diff(obs[perm]) >= 0)
    # within each observation, the hypotheses: a key of any order
    key = rng.integers(0, 3 * spread, len(c))
    hid, hfirst = gk.by_hypothesis(perm, obs, key)
    pairs = list(zip(obs.tolist(), key.tolist(), strict=True))
    assert hid.tolist() == numbered(pairs)
    assert [pairs[i] for i in hfirst.tolist()] == sorted(set(pairs))


def test_groups_by_observation_give_way_out_of_order() -> None:
    """Rows not in choice order: None (the caller sorts them itself)."""
    c = np.array([0, 2, 1], np.int64)
    with rows.running_kernels(True):
        assert gk.by_observation(rows.compiled_on(), c, c, c, c) is None


def test_least_counts_and_hashes_by_loops() -> None:
    rng = np.random.default_rng(3)
    counts = rng.integers(0, 4, (50, 2))
    tid = rng.integers(0, 50, 2000)
    group = np.sort(rng.integers(0, 300, 2000))
    n = int(group.max()) + 1
    got_rows, got_by = gk.least_counts(counts, tid, group, n)
    least = {}
    for t, g in zip(tid.tolist(), group.tolist(), strict=True):
        least[g] = tuple(min(a, b) for a, b in zip(least.get(g, (9, 9)),
                                                   counts[t].tolist(), strict=True))
    want = [i for i, g in enumerate(group.tolist()) if any(least[g])]
    assert got_rows.tolist() == want
    assert [tuple(x) for x in got_by.tolist()] == [least[group[i]] for i in want]
    codes = rng.integers(0, 2**40, 500)
    idx = rng.integers(0, 20, 500)
    out = np.zeros(20, np.uint64)
    gk.hash_add(out, idx, codes)
    mask = (1 << 64) - 1
    want_hash = [0] * 20
    for x, i in zip(codes.tolist(), idx.tolist(), strict=True):
        z = (x + 0x9E3779B97F4A7C15) & mask
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & mask
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
        want_hash[i] = (want_hash[i] + (z ^ (z >> 31))) & mask
    assert out.tolist() == want_hash


def build(model, merge: bool = False):
    return belief_product(model.game, to_dta(model.spec), model.distributions,
                          dict(model.sensors), model.epsilon, max_states=10**6,
                          late_reports=False, merge=merge)


@pytest.mark.parametrize("case", ["one camera", "two cameras", "a delay",
                                  "may never come"])
def test_compiled_level_equals_one_state_at_a_time(case: str) -> None:
    """Every level by the kernels (forced on, the cases being small): the states, their
    order, posteriors, transitions and moves of the build one state at a time."""
    model = CASES[case]()
    with rows.running_kernels(True):
        belief = build(model)
        assert_same(belief, reference(model, belief))


def test_false_alarms_compiled_equals_numpy() -> None:
    """False alarms (the least counts' kernel) and the merge: the kernels' product is
    the NumPy lines', to the bit."""
    model = with_sensors("bus_grid.toml", {"b2": Sensor(0.8, false_alarm=0.1)}, 0.2)
    for merge in (True, False):
        with rows.running_kernels(False):
            plain = build(model, merge)
        with rows.running_kernels(True):
            fast = build(model, merge)
        for a, b in ((fast.mdp.matrix.data, plain.mdp.matrix.data),
                     (fast.mdp.matrix.indices, plain.mdp.matrix.indices),
                     (fast.mdp.row_groups, plain.mdp.row_groups)):
            assert np.array_equal(a, b)
        assert fast.mdp.states == plain.mdp.states
        assert list(fast.moves) == list(plain.moves)
        for key in list(fast.moves)[:50]:
            assert fast.moves[key] == plain.moves[key]


def test_states_made_on_demand_are_the_records() -> None:
    """The records made when asked for: each an InfoState whose posterior sums to one
    (or an absorbing record), the same by index, by slice, by iteration and after
    pickling; ``absorbing`` marks exactly the Absorbing records."""
    model = CASES["two cameras"]()
    mdp = build(model, merge=True).mdp
    states = mdp.states
    assert isinstance(states, InfoStates)
    listed = list(states)
    assert len(listed) == len(states) == mdp.n_states
    assert states[-1] == listed[-1] and states[1:4] == tuple(listed[1:4])
    with pytest.raises(IndexError):
        states[len(states)]
    for s in listed:
        if isinstance(s, InfoState):
            assert abs(sum(s.weights) - 1.0) < 1e-12
            assert list(s.hypotheses) == sorted(s.hypotheses)
    mask = states.absorbing()
    assert mask.tolist() == [isinstance(s, Absorbing) for s in listed]
    assert mask[mdp.target].all() and mask[mdp.sink].all()
    again = pickle.loads(pickle.dumps(states))
    assert again == states == tuple(listed)

"""The information states' key table off the compiled kernels (:class:`Keys`' dict, each
distinct key of a chunk looked up once) against a plain enumeration: every row's state,
``-1 - k`` for the ``k``-th key not met before (in the order the rows come), the first
row of each new key; and the whole build on the small cases against the one-state-at-a-
time reference (tests/test_sensing_build.py's)."""

from __future__ import annotations

import numpy as np
import pytest
from test_sensing_build import CASES, assert_same, reference

from mitld_lp.automata.translate import to_dta
from mitld_lp.sensing import rows
from mitld_lp.sensing.belief import belief_product
from mitld_lp.sensing.keys import Keys


def enumerate_match(table: dict, cols: tuple[np.ndarray, ...]) -> tuple[list, list, list]:
    """A chunk's states, new-key numbers and first rows, one row at a time."""
    out, reps, fresh = [], [], {}
    for i in range(len(cols[0])):
        key = tuple(int(c[i]) for c in cols)
        if key in table:
            out.append(table[key])
        else:
            if key not in fresh:
                fresh[key] = -1 - len(reps)
                reps.append(i)
            out.append(fresh[key])
    return out, reps, list(fresh)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dict_keys_equal_a_plain_enumeration(seed: int) -> None:
    rng = np.random.default_rng(seed)
    keys, table = Keys(3), {}
    state = 0
    with rows.running_kernels(False) as on:
        assert not on
        for m in (1, 7, 400, 3000):
            # few distinct keys, repeated; the last column a full-range hash
            pool = np.stack([rng.integers(-2, 5, 40), rng.integers(0, 3, 40),
                             rng.integers(np.iinfo(np.int64).min, np.iinfo(np.int64).max,
                                          40, dtype=np.int64)], 1)
            pick = pool[rng.integers(0, 40, m)]
            cols = tuple(np.ascontiguousarray(pick[:, j]) for j in range(3))
            want_out, want_reps, new = enumerate_match(table, cols)
            out, reps = keys.match(cols)
            assert out.tolist() == want_out
            assert reps.tolist() == want_reps
            states = np.arange(state, state + len(new), dtype=np.int64)
            keys.settle(states)
            table.update(zip(new, states.tolist(), strict=True))
            state += len(new)
    assert keys.table == table


@pytest.mark.parametrize("case", ["two cameras", "a safety part"])
def test_build_off_the_kernels_equals_one_state_at_a_time(case: str) -> None:
    model = CASES[case]()
    with rows.running_kernels(False):
        belief = belief_product(model.game, to_dta(model.spec), model.distributions,
                                dict(model.sensors), model.epsilon, max_states=10**6,
                                late_reports=False, merge=False)
    assert_same(belief, reference(model, belief))

"""The certificate's chain where its solved states are one level's components (their
rows and block the chain itself, no copies) and where they are not (the copies): its
values against ``numpy.linalg.solve`` of ``(I - Q) v = b`` and its slack ``W`` against
the same solve of ``(I - Q) W = delta v`` (``delta`` from the module's rule, computed
here from the values returned); and the repair's pattern by column against a loop over
every entry."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers.certify_chain import RowModel, chain
from mitld_lp.solvers.certify_repair import Rows, readers_by_column
from mitld_lp.solvers.rounding import rounding


def _model(seed: int, two_levels: bool) -> tuple[RowModel, np.ndarray, np.ndarray]:
    """A model of one choice a state: states 0 (target) and 1 (sink), then transient
    states ``2..n-1`` on a cycle (each to the next, to the target and to the sink; in
    ``two_levels``, the second half's cycle leads into the first's, not back)."""
    rng = np.random.default_rng(seed)
    n = 40
    dense = np.zeros((n, n))
    dense[0, 0] = dense[1, 1] = 1.0
    half = 2 + (n - 2) // 2
    for s in range(2, n):
        nxt = s + 1 if s + 1 < n else 2
        if two_levels and s == half - 1:
            nxt = 2  # the first half's cycle closed on itself
        if two_levels and s == n - 1:
            nxt = half  # the second half's too, after a step into the first below
            dense[s, 2] = 0.1
        p = rng.uniform(0.05, 0.3, size=2)
        dense[s, 0] += p[0]
        dense[s, 1] += p[1]
        dense[s, nxt] += 1.0 - dense[s].sum()
    m = sp.csr_array(dense)
    m.sort_indices()
    model = RowModel(m, np.arange(n + 1), 2)
    target = np.zeros(n, dtype=bool)
    target[0] = True
    policy = np.arange(n)
    policy[0] = -1
    return model, target, policy


@pytest.mark.parametrize("two_levels", [False, True])
@pytest.mark.parametrize("seed", [0, 1])
def test_chain_values_and_slack_against_numpy_solve(seed: int, two_levels: bool) -> None:
    model, target, policy = _model(seed, two_levels)
    rnd = rounding(model.matrix)
    ch = chain(model, target, policy, rnd)  # type: ignore[arg-type]
    idx = np.flatnonzero(ch.solved)
    assert idx.tolist() == list(range(2, model.n_states))
    dense = model.matrix.toarray()
    q = dense[np.ix_(idx, idx)]
    b = dense[idx, 0]
    v = np.linalg.solve(np.eye(idx.size) - q, b)
    assert np.allclose(ch.values[idx], v, rtol=1e-12, atol=0.0)
    assert ch.values[0] == 1.0 and ch.values[1] == 0.0
    # W = delta v + Q W, delta v = 2 (|v - (b + Q v)| + kappa v) on the returned v
    got = ch.values[idx]
    kappa = 1.0 - rnd.low_of[rnd.count[policy[idx]]]
    need = 2.0 * (np.abs(got - (b + q @ got)) + kappa * got)
    w = np.linalg.solve(np.eye(idx.size) - q, need)
    assert np.all(ch.slack[idx] > 0)
    assert np.allclose(ch.slack[idx], w, rtol=1e-6, atol=0.0)


def _robust_rows(seed: int) -> Rows:
    """Rows grouped into choices by nature and choices into states, some state
    without a choice and some columns no row reads."""
    rng = np.random.default_rng(seed)
    n = 30
    choices = rng.integers(0, 3, size=n)  # per state (0: none)
    groups = np.concatenate([[0], np.cumsum(choices)])
    per_choice = rng.integers(1, 3, size=int(groups[-1]))
    nature = np.concatenate([[0], np.cumsum(per_choice)])
    rows = int(nature[-1])
    dense = (rng.random((rows, n)) < 0.15) * rng.random((rows, n))
    dense[:, n - 3:] = 0.0  # columns no row holds
    return Rows(sp.csr_array(dense), groups.astype(np.int64), nature.astype(np.int64))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_readers_by_column_against_every_entry(seed: int) -> None:
    st = _robust_rows(seed)
    dense = st.matrix.toarray()
    # each row's state by a walk over the groups, not Rows.row_state
    state_of_row = {}
    for s in range(st.n_states):
        for c in range(int(st.groups[s]), int(st.groups[s + 1])):
            for r in range(int(st.nature[c]), int(st.nature[c + 1])):
                state_of_row[r] = s
    col_ptr, col_state = readers_by_column(st)
    assert col_ptr.size == dense.shape[1] + 1
    for j in range(dense.shape[1]):
        want = sorted(state_of_row[r] for r in np.flatnonzero(dense[:, j]))
        got = col_state[col_ptr[j]:col_ptr[j + 1]].tolist()
        assert got == want, j

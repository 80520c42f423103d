"""The single states' entries read in batches (rows.off_diagonal_entries, the solve
stage's memory peak): the entries of each row but its self-loop, in CSR order, against a
loop over the dense matrix; ``local`` held in 4 bytes an entry; batches that split the
rows give what one batch gives; SingleLevels holds them so on an analysed product."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from test_single_levels import layered_mdp

from mitld_lp.solvers import rows as rows_mod
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.rows import off_diagonal_entries
from mitld_lp.solvers.topological import SingleLevels, blocks


def _by_loop(dense: np.ndarray, rows: np.ndarray, row_state: np.ndarray):
    """The expected entries, row by row over the dense matrix (no CSR arrays read)."""
    local, cols, vals = [], [], []
    for i, r in enumerate(rows):
        for c in range(dense.shape[1]):
            if dense[r, c] != 0.0 and c != row_state[i]:
                local.append(i)
                cols.append(c)
                vals.append(dense[r, c])
    return np.array(local), np.array(cols), np.array(vals)


@pytest.mark.parametrize("batch", [1, 3, 1 << 16])
def test_off_diagonal_entries_are_the_rows_entries_but_the_self_loop(
        monkeypatch: pytest.MonkeyPatch, batch: int) -> None:
    monkeypatch.setattr(rows_mod, "BATCH", batch)
    rng = np.random.default_rng(4)
    dense = np.where(rng.random((9, 7)) < 0.4, rng.random((9, 7)), 0.0)
    dense[2] = 0.0  # a row without entries
    matrix = sp.csr_array(dense)
    rows = np.array([5, 2, 0, 8, 5, 3, 7])
    row_state = rng.integers(0, 7, size=rows.size)
    row_state[0] = np.flatnonzero(dense[5])[0]  # a self-loop that is stored
    local, cols, vals = off_diagonal_entries(matrix, rows, row_state)
    want = _by_loop(dense, rows, row_state)
    assert local.dtype == np.int32
    assert cols.dtype == matrix.indices.dtype and vals.dtype == np.float64
    assert np.array_equal(local, want[0]) and np.array_equal(cols, want[1])
    assert np.array_equal(vals, want[2])
    assert want[0].size < sum(np.count_nonzero(dense[r]) for r in rows)  # one dropped


def test_off_diagonal_entries_of_no_rows_are_empty() -> None:
    matrix = sp.csr_array(np.eye(3))
    local, cols, vals = off_diagonal_entries(matrix, np.zeros(0, dtype=np.int64),
                                             np.zeros(0, dtype=np.int64))
    assert local.size == cols.size == vals.size == 0
    assert local.dtype == np.int32 and vals.dtype == np.float64


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_single_levels_hold_each_choices_entries_but_its_self_loop_in_int32(
        sense: Sense) -> None:
    mdp, _, _ = layered_mdp(3, depth=12)
    q, _ = analyse(mdp, mdp.target, sense=sense)
    singles = SingleLevels(q, blocks(q))
    assert singles.choices.size > 0
    assert singles.local.dtype == np.int32
    dense = q.matrix.toarray()
    # each choice's state, from the states' choice pointers (the walks keep no owner)
    owner = np.repeat(np.arange(singles.states.size), np.diff(singles.state_choice))
    want = _by_loop(dense, singles.choices, singles.states[owner])
    assert np.array_equal(singles.local, want[0])
    assert np.array_equal(singles.cols, want[1]) and np.array_equal(singles.vals, want[2])
    # each choice's entries start where the walks read them
    for c in range(singles.choices.size):
        a, z = singles.choice_entry[c], singles.choice_entry[c + 1]
        assert np.all(singles.local[a:z] == c)
        assert np.all(want[0][a:z] == c)

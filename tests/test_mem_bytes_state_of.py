"""``MDPShape.state_of`` in 4 bytes an entry where the states fit, searched a slice at a
time (mem-bytes), and ``memory_stages``'s sites alive at the traced peak."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import mitld_lp.mdp as mdp_module
from mitld_lp.mdp import MDP


def _mdp(choices_per_state: list[int]) -> MDP:
    n = len(choices_per_state)
    row_groups = np.concatenate([[0], np.cumsum(choices_per_state)]).astype(np.int64)
    m = int(row_groups[-1])
    matrix = sp.csr_array((np.ones(m), np.zeros(m, dtype=np.int32),
                           np.arange(m + 1, dtype=np.int32)), shape=(m, n))
    none = np.zeros(n, dtype=bool)
    return MDP(row_groups=row_groups, choice_actions=np.zeros(m, dtype=np.int32),
               action_names=("a",), initial=0, target=none, sink=none.copy(),
               truncated=none.copy(), states=tuple(range(n)), matrix=matrix)


@pytest.mark.parametrize("slice_", [1, 3, 1 << 16])
def test_state_of_is_each_choices_owner_in_any_order(monkeypatch, slice_) -> None:
    rng = np.random.default_rng(7)
    per = rng.integers(1, 5, size=200).tolist()
    mdp = _mdp(per)
    # the owner of every choice, written out state by state (not a search)
    owner = [s for s, k in enumerate(per) for _ in range(k)]
    choices = rng.permutation(mdp.n_choices)[:333] if mdp.n_choices > 333 else \
        rng.permutation(mdp.n_choices)
    choices = np.concatenate([choices, choices[:5], [0, mdp.n_choices - 1]])
    monkeypatch.setattr(mdp_module, "STATE_OF_SLICE", slice_)
    got = mdp.state_of(choices)
    assert got.dtype == np.int32  # 200 states fit in 4 bytes
    assert got.tolist() == [owner[c] for c in choices.tolist()]
    assert got.tolist() == mdp.choice_state()[choices].tolist()
    assert mdp.state_of(np.zeros(0, dtype=np.int64)).shape == (0,)
    # a list, and a 2-d array (shape kept, the plain search)
    assert mdp.state_of([0, int(per[0])]).tolist() == [0, 1]
    grid = choices[:6].reshape(2, 3)
    assert mdp.state_of(grid).tolist() == [[owner[c] for c in r] for r in grid.tolist()]


def test_state_of_goes_wide_when_the_states_do_not_fit(monkeypatch) -> None:
    mdp = _mdp([2, 1, 3])
    monkeypatch.setattr(mdp_module, "index_dtype", lambda n: np.int64)
    got = mdp.state_of(np.array([5, 0, 2, 3]))
    assert got.dtype == np.int64 and got.tolist() == [2, 0, 1, 2]


def test_the_stage_table_names_the_sites_alive_at_the_peak() -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import memory_stages

    rows = {"synthesize": dict(calls=1, peak=200.0, kept=150.0, without_numba=200.0)}
    shown = memory_stages.text("x", dict(
        stages=rows, base_mb=1.0, numba_mb=0, transitions=2**20, top_where="", top=[],
        peak_top=[("mitld_lp/a.py:3", 12.5)], peak_top_at=99.0,
        peak_top_where="iteration, return: mitld_lp/a.py:3 (f)"))
    assert "near the traced peak (99.0 bytes a transition" in shown
    assert "- `mitld_lp/a.py:3`: 12.5" in shown
    plain = memory_stages.text("x", dict(stages=rows, base_mb=1.0, numba_mb=0,
                                         transitions=2**20, top_where="", top=[]))
    assert "near the traced peak" not in plain


def test_the_trace_snapshots_an_array_alive_only_inside_a_call() -> None:
    """A 16 MB array that lives only while a package function runs is named by the
    at-peak snapshot (taken at that function's return, its locals alive), while the
    size at the stage's exit no longer holds it."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import memory_stages

    from mitld_lp.util import arrays

    def work() -> np.ndarray:
        big = arrays.concatenate([np.ones(1 << 21)], np.float64)  # 16 MB, a package call
        return np.asarray([big.sum()])

    tracker = memory_stages.Tracker(traced=True, at_peak=True)
    _, out = tracker.run(work, lambda r: 1 << 20)
    named = dict(out["peak_top"])
    assert any(w.startswith("mitld_lp/util/arrays.py") for w in named)
    assert sum(b for w, b in named.items() if w.startswith("mitld_lp/util/arrays.py")) >= 15
    assert out["stages"]["synthesize"]["traced_kept"] < 1

"""What the sensed case holds at its peaks (docs/results.md, ``sensed-84``):

- the build's hypotheses grow by doubling without writing the new tail
  (``sensing.rows.grown``: ``np.resize`` wrote every page of it);
- the build's chunks are cut where their rows are foreseen past ``chunks.CHUNK_ROWS``
  (``RowGauge``), and the product is the same to the bit however they are cut;
- the single states' walks keep no per-entry choice array where they are compiled
  (``SingleLevels.local`` made from the pointers when asked)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from test_sensing_build import CASES, assert_same, reference
from test_single_levels import layered_mdp

from mitld_lp.automata.translate import to_dta
from mitld_lp.sensing import chunks, frontier
from mitld_lp.sensing.belief import belief_product
from mitld_lp.sensing.rows import grown
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.topological import SingleLevels, blocks

ROOT = Path(__file__).resolve().parent.parent


def test_grown_keeps_the_prefix_and_the_dtype() -> None:
    for x in (np.arange(7, dtype=np.int64) * 3 - 5, np.linspace(0.1, 0.9, 7)):
        out = grown(x, 5, 16)
        assert out.dtype == x.dtype and out.shape == (16,)
        assert np.array_equal(out[:5], x[:5])


_CHILD = """
import json, sys
import numpy as np
from mitld_lp.sensing.rows import grown

def rss():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS"):
                return int(line.split()[1]) * 1024

size = 8 << 20  # 64 MB of int64
x = np.arange(1024, dtype=np.int64)
a = rss()
kept = grown(x, 1024, size)
b = rss()
del kept
c = rss()
old = np.resize(x, size)
d = rss()
print(json.dumps(dict(grown=b - a, resize=d - c)))
"""


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="Linux's /proc")
def test_grown_leaves_the_new_tail_unwritten() -> None:
    """In a process of its own: growing 1,024 values to 64 MB makes at most a few
    pages resident; ``np.resize`` (what the build did) makes all of them resident."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", _CHILD], cwd=ROOT, env=env,
                         capture_output=True, text=True, check=True)
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["resize"] > 48 << 20  # the route it replaces: every page written
    assert got["grown"] < 4 << 20, got


def _build(model):
    return belief_product(model.game, to_dta(model.spec), model.distributions,
                          dict(model.sensors), model.epsilon, max_states=10**6)


def _arrays(belief) -> dict[str, np.ndarray]:
    m = belief.mdp
    return {"data": m.matrix.data, "indices": m.matrix.indices, "indptr": m.matrix.indptr,
            "row_groups": m.row_groups, "choice_actions": m.choice_actions,
            "target": m.target, "sink": m.sink, "truncated": m.truncated}


def test_build_is_the_same_with_the_old_growth_and_however_its_chunks_are_cut(
        monkeypatch) -> None:
    """The product (every array, to the bit, the same dtypes) built as the base built
    it (``np.resize``, no bound on rows), as now, and with chunks of very few rows; the
    last also equals the one-state-at-a-time construction (tests/test_sensing_build.py)."""
    model = CASES["two cameras"]()
    calls = {"grown": 0, "expand": 0}
    expand = frontier.FrontierBuilder.expand

    def counted(self, a, b):
        calls["expand"] += 1
        return expand(self, a, b)

    monkeypatch.setattr(frontier.FrontierBuilder, "expand", counted)
    now = _build(model)
    chunks_now = calls["expand"]
    with monkeypatch.context() as m:
        m.setattr(frontier, "grown", lambda x, used, size: np.resize(x, size))
        m.setattr(chunks, "CHUNK_ROWS", 10**12)
        old = _build(model)
    calls["expand"] = 0

    def counted_grown(x, used, size):
        calls["grown"] += 1
        return grown(x, used, size)

    with monkeypatch.context() as m:
        m.setattr(frontier, "grown", counted_grown)
        m.setattr(chunks, "CHUNK_ROWS", 64)
        small = _build(model)
    assert calls["grown"] > 0  # the hypotheses outgrew their first arrays
    assert calls["expand"] > chunks_now  # the rows' bound cut more chunks
    want = {"data": np.float64, "indices": np.int32, "indptr": np.int32,
            "row_groups": np.int64, "choice_actions": np.int32, "target": np.bool_,
            "sink": np.bool_, "truncated": np.bool_}
    for built in (now, small):
        for name, x in _arrays(built).items():
            y = _arrays(old)[name]
            assert x.dtype == y.dtype == want[name], name
            assert np.array_equal(x, y), name
    assert now.mdp.initial == old.mdp.initial == small.mdp.initial
    with monkeypatch.context() as m:  # as tests/test_sensing_build.py's reference builds
        m.setattr(chunks, "CHUNK_ROWS", 64)
        ref = belief_product(model.game, to_dta(model.spec), model.distributions,
                             dict(model.sensors), model.epsilon, max_states=10**6,
                             late_reports=False, merge=False)
    assert_same(ref, reference(model, ref))


def test_row_gauge_bounds_the_next_chunk() -> None:
    """Hand counts: 8 rows a hypothesis bound a chunk to CHUNK_ROWS / 8 hypotheses; a
    rate within the bound leaves CHUNK_HYPOTHESES; no chunk yet, CHUNK_HYPOTHESES."""
    gauge = chunks.RowGauge()
    assert gauge.limit() == chunks.CHUNK_HYPOTHESES
    gauge.made(1000, 8000)
    assert gauge.limit() == min(chunks.CHUNK_HYPOTHESES, chunks.CHUNK_ROWS // 8)
    gauge.made(1000, 1000)
    assert gauge.limit() == chunks.CHUNK_HYPOTHESES
    gauge.made(1, 10**12)
    assert gauge.limit() == 1  # one state's hypotheses at the least
    gauge.made(0, 5)  # nothing to learn from
    assert gauge.limit() == 1
    held = np.array([5, 5, 5])
    assert chunks.chunk_end(held, 0, 10) == 2 and chunks.chunk_end(held, 0, 4) == 1


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_compiled_single_levels_hold_no_per_entry_choices(sense: Sense) -> None:
    """The compiled walks' SingleLevels keeps no copy of the rows (single-85b: they
    read the quotient's CSR arrays in place): its :meth:`entries` are the NumPy walks'
    arrays (values and int32 ``local``), and tracemalloc counts no more held than the
    per-state and per-choice arrays the walks read (the copy would add 16-20 bytes a
    kept entry)."""
    pytest.importorskip("numba")
    mdp, _, _ = layered_mdp(5, depth=400, width=6)
    q, _ = analyse(mdp, mdp.target, sense=sense)
    b = blocks(q)
    plain = SingleLevels(q, b, compiled=False)
    SingleLevels(q, b, compiled=True)  # the compiled walks' module imported untraced
    tracemalloc.start()
    try:
        start = tracemalloc.get_traced_memory()[0]
        wide = SingleLevels(q, b, compiled=True)
        held = tracemalloc.get_traced_memory()[0] - start
    finally:
        tracemalloc.stop()
    assert wide.kernels is not None and wide._local is None and wide.cols is None
    assert wide.rows.indices is q.matrix.indices and wide.rows.data is q.matrix.data
    ptr, local, cols, vals = wide.entries()
    assert plain.local.dtype == local.dtype == np.int32
    assert np.array_equal(plain.local, local)
    assert np.array_equal(plain.cols, cols) and np.array_equal(plain.vals, vals)
    assert np.array_equal(plain.choice_entry, ptr)
    for name in ("state_choice", "leave"):
        assert np.array_equal(getattr(plain, name), getattr(wide, name)), name
    arrays = {id(x): x.nbytes for x in (wide.states, wide.choices, wide.leave,
                                        wide.level_state, wide.state_choice)}
    need = sum(arrays.values())
    copy_bytes = cols.nbytes + vals.nbytes
    assert copy_bytes > 8192  # large enough for the bound below to see it
    assert held <= need + 4096, (held, need)


def test_issue45_build_bounds_its_largest_chunk_by_rows(monkeypatch) -> None:
    """On issue 45's sensed case the kernel's row pages hold the largest chunk's rows
    (docs/results.md, ``sensed-84``): without the rows' bound one chunk made 207,978
    rows; with it the largest makes at most 1.5 x :data:`chunks.CHUNK_ROWS` (189,008
    measured: the gauge reads the last chunk's rate, which errs low)."""
    from test_sensed_solve_memory import _issue45

    made: list[int] = []
    inner = chunks.RowGauge.made

    def counted(self, hypotheses: int, rows: int) -> None:
        made.append(rows)
        inner(self, hypotheses, rows)

    monkeypatch.setattr(chunks.RowGauge, "made", counted)
    belief = _build(_issue45())
    assert belief.mdp.n_transitions > 10**6
    assert max(made) <= 1.5 * chunks.CHUNK_ROWS, max(made)
    made.clear()
    monkeypatch.setattr(chunks, "CHUNK_ROWS", 10**12)  # the base's chunks
    _build(_issue45())
    assert max(made) > 1.5 * 131_072  # the bound is what keeps the rows down

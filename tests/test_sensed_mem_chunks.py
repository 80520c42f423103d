"""The sensed build's memory: chunks bounded by their hypotheses, the transitions kept
per chunk in their final dtypes and joined once, and the build's arrays freed.

A chunk of one state splits every level of the build into as many parts as it has
states, so the parts' assembly (each state's choices, each choice's transitions, the
moves' narrowed columns) is exercised far more than by the default bound.  The product
so built is compared with the one-state-at-a-time construction written in
tests/test_sensing_build.py (dictionaries of tuples, the observations grouped by hand)
and its optimum with the exhaustive expectimax over observation histories of
tests/test_sensing.py (no information states at all)."""

from __future__ import annotations

import gc
import weakref

import numpy as np
import pytest
from test_sensing import PMF1, PMF2, SPEC2, TWO, expectimax_many
from test_sensing_build import CASES, assert_same, reference

from mitld_lp import Model, synthesize
from mitld_lp.automata.translate import to_dta
from mitld_lp.sensing import chunks, frontier, rows
from mitld_lp.sensing.belief import belief_product


def _build(model, **kwargs):
    return belief_product(model.game, to_dta(model.spec), model.distributions,
                          dict(model.sensors), model.epsilon, max_states=10**6, **kwargs)


@pytest.mark.parametrize("kernels", [False, True])
@pytest.mark.parametrize("case", ["two cameras", "a safety part"])
def test_one_state_chunks_equal_one_state_at_a_time(monkeypatch, case: str,
                                                    kernels: bool) -> None:
    """Every chunk a single state (the bound met by the first state's hypotheses): the
    same states, rows, posteriors, moves and numbering as the reference built one
    state at a time, NumPy lines and kernels alike."""
    if kernels:
        pytest.importorskip("numba")
    monkeypatch.setattr(chunks, "CHUNK_HYPOTHESES", 1)
    model = CASES[case]()
    with rows.running_kernels(kernels):
        belief = _build(model, late_reports=False, merge=False)
    assert belief.mdp.n_states > 50  # many chunks, many levels
    assert_same(belief, reference(model, belief))


def test_one_state_chunks_optimum_equals_expectimax(monkeypatch) -> None:
    """Two events, each with a camera that misses: the certified bracket of the product
    built a state a chunk holds the expectimax over observation histories."""
    monkeypatch.setattr(chunks, "CHUNK_HYPOTHESES", 1)
    r = synthesize(Model.from_game(TWO, SPEC2, sensors={"b1": {"detect": 0.6},
                                                        "b2": {"detect": 0.4}}))
    assert r.route == "sensed" and r.certified
    exact = expectimax_many(TWO, [(PMF1, 0.6, "A", 1), (PMF2, 0.4, "B", 1)], horizon=5)
    assert r.lower - 1e-7 <= exact <= r.upper + 1e-7


def test_chunk_end_bounds_the_hypotheses() -> None:
    """A chunk takes states while their hypotheses stay within the bound, and always
    its first state (one with more hypotheses than the bound alone)."""
    fb = frontier.FrontierBuilder.__new__(frontier.FrontierBuilder)
    fb.cols = frontier.Columns(6)
    fb.gauge = chunks.RowGauge()  # no chunk made yet: the hypotheses alone bound it
    counts = np.array([3, 4, 2, 9, 1, 1], np.int64)
    fb.cols.extend(tuple(np.zeros(6, np.int64) for _ in range(5)) + (counts,))
    bound = chunks.CHUNK_HYPOTHESES
    try:
        chunks.CHUNK_HYPOTHESES = 9
        # 3 + 4 + 2 = 9 fits, + 9 does not; from state 3: 9 alone; from 4: 1 + 1
        assert [fb.chunk_end(0, 6), fb.chunk_end(3, 6), fb.chunk_end(4, 6)] == [3, 4, 6]
        chunks.CHUNK_HYPOTHESES = 2
        assert fb.chunk_end(0, 6) == 1  # 3 > 2: the first state alone
        assert fb.chunk_end(1, 2) == 2  # never past the level's end
    finally:
        chunks.CHUNK_HYPOTHESES = bound


def test_joined_drops_each_part_once_copied() -> None:
    """The parts' arrays are joined in order into one array of the final dtype, and
    each is dropped from its part as it is copied (the collector off: only reference
    counting frees them), the other columns left."""
    parts = [[np.arange(k, dtype=np.int64), np.arange(k, dtype=np.int32) * 2]
             for k in (3, 0, 5)]
    held = [weakref.ref(p[1]) for p in parts]
    kept = [weakref.ref(p[0]) for p in parts]
    collecting = gc.isenabled()
    gc.disable()
    try:
        out = rows.join_parts(parts, 1, np.int64)
        assert out.dtype == np.int64
        assert out.tolist() == [0, 2, 4] + [0, 2, 4, 6, 8]
        assert all(ref() is None for ref in held)
        assert all(ref() is not None for ref in kept)
    finally:
        if collecting:
            gc.enable()


@pytest.mark.parametrize("kernels", [False, True])
def test_level_arrays_and_state_columns_freed(monkeypatch, kernels: bool) -> None:
    """With the cyclic collector off, no array a level of the build returned (its
    states' choices, the choices' actions and transitions, columns and probabilities),
    nor the rows' pages and keys the levels used, nor the builder's state columns and
    hypotheses outlive ``belief_product``: only
    reference counting frees them, so none holds the solve above the build."""
    if kernels:
        pytest.importorskip("numba")
    held: list[weakref.ref] = []
    expand, build = frontier.FrontierBuilder.expand, frontier.FrontierBuilder.build

    def expanded(self, a, b):
        out = expand(self, a, b)
        # the level's own arrays, the kernel's row pages and the keys' table as they are
        held.extend(weakref.ref(x) for x in (*out, *self.row_work, self.keys.slots,
                                             self.keys.keys))
        return out

    def built(self, *args, **kwargs):
        out = build(self, *args, **kwargs)
        held.extend(weakref.ref(x) for x in (self.hyp_code, self.hyp_weight,
                                             self.cols.data, *self.row_work))
        return out

    model = CASES["two cameras"]()
    with rows.running_kernels(kernels):
        _build(model)  # numba's own cycles made before the count (a cold cache)
    monkeypatch.setattr(frontier.FrontierBuilder, "expand", expanded)
    monkeypatch.setattr(frontier.FrontierBuilder, "build", built)
    collecting = gc.isenabled()
    gc.disable()
    try:
        with rows.running_kernels(kernels):
            belief = _build(model)
        assert belief.mdp.n_transitions > 1000 and len(held) >= 30
        alive = [i for i, ref in enumerate(held) if ref() is not None]
        assert not alive, f"{len(alive)} of the build's {len(held)} arrays outlived it"
    finally:
        if collecting:
            gc.enable()

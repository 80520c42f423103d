"""The compiled breadth-first product loop's memory (:func:`mitld_lp.product.table_levels.
run_compiled`): its buffers start small and grow by doubling, a product larger than the
first buffer comes out as NumPy's levels build it, its calls' traced peak is bounded by
the product's own size (not by a fixed block, nor by the world's unreachable states), and
the rule that decides whether the loop is loaded at all."""

from __future__ import annotations

import importlib.util
import tracemalloc
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from test_product_bfs_kernels import assert_same

from mitld_lp.automata.sta import make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.logic.parser import parse
from mitld_lp.model import bind_distributions
from mitld_lp.product import build, product
from mitld_lp.product import table_levels as tl
from mitld_lp.worlds.table import WorldTable

pytestmark = pytest.mark.skipif(importlib.util.find_spec("numba") is None,
                                reason="needs numba")

LABELS = (frozenset(), frozenset({"goal"}))


class Chain:
    """A table world made with NumPy: state ``s`` has ``width`` actions, each to
    ``s + 1 .. s + 3`` (modulo ``reach``, the states reachable from 0) with fixed odds;
    the states from ``reach`` to ``n`` are never reached (each a self-loop).  Every
    ``goal_every``-th state is labelled goal."""

    ignores_events = True
    event_names: frozenset[str] = frozenset()
    proposition_names = frozenset({"goal"})
    acts = ("a", "b")

    def __init__(self, n: int, reach: int, goal_every: int = 997) -> None:
        self.states = range(n)
        self.initial = 0
        s = np.arange(n, dtype=np.int64)
        label_of = np.where((s % goal_every == goal_every - 1) & (s < reach), 1, 0)
        live = s < reach
        n_act = np.where(live, 2, 1)
        choices = np.concatenate([[0], np.cumsum(n_act)])
        c_state = np.repeat(s, n_act)
        c_rank = np.arange(c_state.size) - choices[c_state]
        c_live = live[c_state]
        row_len = np.where(c_live, 3, 1)
        branches = np.concatenate([[0], np.cumsum(row_len)])
        e_choice = np.repeat(np.arange(c_state.size), row_len)
        e_rank = np.arange(e_choice.size) - branches[e_choice]
        e_state = c_state[e_choice]
        step = 1 + e_rank + c_rank[e_choice]  # action a: +1..+3, b: +2..+4
        targets = np.where(c_live[e_choice], (e_state + step) % reach, e_state)
        odds = np.array([0.5, 0.25, 0.25])
        probs = np.where(c_live[e_choice], odds[np.minimum(e_rank, 2)], 1.0)
        self.table = WorldTable(
            states=self.states, initial=0, label_sets=LABELS,
            label_of=label_of.astype(np.int64), choices=choices.astype(np.int64),
            action_names=self.acts, action_of=c_rank.astype(np.int32),
            branches=branches.astype(np.int64), targets=targets.astype(np.int64),
            probabilities=probs.astype(np.float64), checked=False)

    def as_table(self) -> WorldTable:
        return self.table

    def actions(self, s: Any) -> tuple[str, ...]:  # pragma: no cover - the table is read
        return self.acts if s < self.table.choices.size else ()

    def successors(self, s: Any, a: str, events: frozenset[str]) -> Any:  # pragma: no cover
        raise AssertionError("read from the table")

    def propositions(self, s: Any) -> frozenset[str]:
        return LABELS[int(self.table.label_of[s])]


def task(spec: str) -> Any:
    f = parse(spec)
    return make_sta(to_dta(f), bind_distributions(f), 1e-6)


def built(world: Chain, sta: Any, monkeypatch: pytest.MonkeyPatch, *, compiled: bool,
          ) -> tuple[Any, list[int], list[int]]:
    """The product by NumPy's levels alone, or with the compiled loop's load counted as
    paid (every level after the first by the loop); the entries each of the loop's calls
    had room for, and each call's traced peak above the traced size at its start."""
    from mitld_lp.product import bfs_kernels
    from mitld_lp.util import kernel_loader

    rooms: list[int] = []
    peaks: list[int] = []
    real_kernel = bfs_kernels.table_levels
    real_run = tl.run_compiled

    def kernel(*a: Any) -> Any:
        rooms.append(int(a[21].shape[0]))  # cols: as many as the room's entries
        return real_kernel(*a)

    def run(*a: Any) -> Any:
        start = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        try:
            return real_run(*a)
        finally:
            peaks.append(tracemalloc.get_traced_memory()[1] - start)

    monkeypatch.setattr(tl, "COMPILED", compiled)
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: True)
    monkeypatch.setattr(bfs_kernels, "table_levels", kernel)
    monkeypatch.setattr(build, "run_compiled", run)
    tracemalloc.start()
    try:
        mdp = product(world, sta, max_states=10**7)
    finally:
        tracemalloc.stop()
    return mdp, rooms, peaks


@pytest.mark.parametrize("spec", ["F goal", "G !goal", "G (goal -> F[0,9] goal)"])
def test_the_buffers_grow_and_the_product_is_numpys(
        spec: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A product of ~120,000 transitions (6 a state), many times the first buffer
    (4,096 entries): the room grows call after call, at most doubling each time, and
    the arrays are NumPy's to the bit."""
    world, sta = Chain(20_000, 20_000), task(spec)
    expected, _, _ = built(world, sta, monkeypatch, compiled=False)
    mdp, rooms, _ = built(world, sta, monkeypatch, compiled=True)
    assert expected.n_transitions > 16 * tl._MIN_ENTRIES
    assert rooms and rooms[0] < expected.n_transitions  # the first buffer is too small
    assert rooms[-1] >= 2 * rooms[0]  # grown
    assert all(b <= 2 * a for a, b in zip(rooms, rooms[1:], strict=False))  # by doubling
    assert max(rooms) <= expected.n_transitions  # never past the product's own size
    assert_same(mdp, expected)


def test_the_loops_peak_is_bounded_by_the_products_size(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A world of 400,000 states of which 3,000 are reachable: each call of the loop
    peaks (tracemalloc) within an estimate from the product alone: its buffers, at most
    24 bytes an entry for twice the product's transitions (a doubling's overshoot), the
    keys' (8 bytes) and the dense index's (4 bytes a slot, at most 8 slots a state past
    64K slots) growth by doubling, and 64 KB of small objects.  A fixed block of 4M
    entries (~100 MB), or an index sized for every key of the world (3.2 MB here), is
    far above it."""
    world, sta = Chain(400_000, 3_000), task("F goal")
    expected, _, _ = built(world, sta, monkeypatch, compiled=False)
    mdp, rooms, peaks = built(world, sta, monkeypatch, compiled=True)
    assert_same(mdp, expected)
    n, t = expected.n_states, expected.n_transitions
    bound = 24 * 2 * t + 8 * 2 * n + 4 * 2 * max(1 << 16, 8 * n) + (64 << 10)
    assert peaks and max(peaks) <= bound, (max(peaks), bound, rooms)


def test_the_load_is_wanted_where_it_pays_in_time_and_memory(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """:func:`~mitld_lp.product.table_levels.compiled_wanted` on figures worked by hand
    (the build budget's 96 bytes a state and 32 a transition; a load of 48 MiB =
    50,331,648 bytes at most 2% of the product still to come; a million states left pay
    its 0.04 s twice at 0.08 us each)."""
    from mitld_lp.util import kernel_loader

    lean = SimpleNamespace(table_steps=np.zeros(1), batches=0)
    paid = [False]
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: paid[0])
    monkeypatch.setattr(tl, "loop_cached", lambda: False)  # the cold rule's figures
    # 2M states at 2 transitions each: 2% of 2e6 * 160 B = 6.4 MB < 48 MiB: not loaded
    assert not tl.compiled_wanted(lean, 2_000_000, 0, 1, 2.0)
    # 20M states: 2% of 20e6 * 160 B = 64 MB >= 48 MiB, and 20M >= 1M states: loaded
    assert tl.compiled_wanted(lean, 20_000_000, 0, 1, 2.0)
    # ... but not past half the world (the states left may never be reached)
    assert not tl.compiled_wanted(lean, 20_000_000, 10_000_000, 1, 2.0)
    # 16M states left: 2% of 16e6 * 160 B = 51.2 MB >= 48 MiB; 15M: 48.0 MB < 48 MiB
    assert tl.compiled_wanted(lean, 20_000_000, 4_000_000, 1, 2.0)
    assert not tl.compiled_wanted(lean, 20_000_000, 5_000_000, 1, 2.0)
    # firewire_dl 3-600's figures (168,411 world states, 1.17 transitions a state,
    # a frontier of ~265): not loaded, however thin; loaded once paid
    lean.batches = 100
    assert not tl.compiled_wanted(lean, 168_411, 20_000, 265, 1.17)
    paid[0] = True
    assert tl.compiled_wanted(lean, 168_411, 20_000, 265, 1.17)
    monkeypatch.setattr(tl, "COMPILED", False)
    assert not tl.compiled_wanted(lean, 168_411, 20_000, 265, 1.17)

"""A plain table world's levels by the compiled breadth-first loop
(:mod:`mitld_lp.product.bfs_kernels`, driven by :func:`mitld_lp.product.table_levels.
run_compiled`): the same arrays as NumPy's levels (numpy.testing), and the product a
breadth-first search written here builds state by state, on random table worlds and
automata; with the loop stopped and resumed at every buffer's edge, switched to midway,
and under the state budget."""

from __future__ import annotations

import importlib.util
from collections.abc import Hashable
from typing import Any

import numpy as np
import numpy.testing as npt
import pytest

from mitld_lp.automata.sta import make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.logic.parser import parse
from mitld_lp.model import bind_distributions
from mitld_lp.product import ProductTooLarge, build, product
from mitld_lp.product import table_levels as tl
from mitld_lp.worlds.table import WorldTable

pytestmark = pytest.mark.skipif(importlib.util.find_spec("numba") is None,
                                reason="needs numba")

SPECS = ["F goal", "F[0,5] goal", "!bad U goal", "G !bad", "(F[0,7] goal) & F mid",
         "F (mid & F[0,3] goal)", "G (mid -> F[0,2] goal)"]
LABELS = (frozenset(), frozenset({"goal"}), frozenset({"bad"}), frozenset({"mid"}),
          frozenset({"goal", "mid"}))


class Table:
    """A random world given as a table alone (its game protocol reads the same arrays):
    successors near the state (a thin frontier of many levels), rows that may name a
    state twice where ``repeat``."""

    ignores_events = True
    event_names: frozenset[str] = frozenset()
    proposition_names = frozenset({"goal", "bad", "mid"})
    acts = ("a", "b", "c")

    def __init__(self, seed: int, n: int, *, repeat: bool) -> None:
        rng = np.random.default_rng(seed)
        self.states = tuple(range(n))
        self.initial = 0
        label_of = rng.choice(len(LABELS), size=n, p=[0.9, 0.01, 0.02, 0.06, 0.01])
        label_of[0] = 0
        choices, action_of, branches, targets, probs = [0], [], [0], [], []
        for s in range(n):
            for a in rng.choice(3, size=int(rng.integers(1, 4)), replace=False).tolist():
                t = (s + rng.integers(-2, 4, size=int(rng.integers(1, 6)))) % n
                if not repeat:
                    t = np.unique(t)
                w = rng.random(t.size) + 0.05
                targets += t.tolist()
                probs += (w / w.sum()).tolist()
                branches.append(len(targets))
                action_of.append(a)
            choices.append(len(action_of))
        self.table = WorldTable(
            states=self.states, initial=0, label_sets=LABELS,
            label_of=label_of.astype(np.int64), choices=np.array(choices, dtype=np.int64),
            action_names=self.acts, action_of=np.array(action_of, dtype=np.int32),
            branches=np.array(branches, dtype=np.int64),
            targets=np.array(targets, dtype=np.int64),
            probabilities=np.array(probs, dtype=np.float64), checked=False)

    def as_table(self) -> WorldTable:
        return self.table

    def actions(self, s: Hashable) -> tuple[str, ...]:
        t = self.table
        return tuple(self.acts[int(t.action_of[c])]
                     for c in range(int(t.choices[s]), int(t.choices[s + 1])))

    def successors(self, s: Any, a: str, events: frozenset[str]) -> Any:
        t = self.table
        for c in range(int(t.choices[s]), int(t.choices[s + 1])):
            if self.acts[int(t.action_of[c])] == a:
                at = range(int(t.branches[c]), int(t.branches[c + 1]))
                return tuple((int(t.targets[j]), float(t.probabilities[j])) for j in at)
        raise KeyError(a)

    def propositions(self, s: Any) -> frozenset[str]:
        return LABELS[int(self.table.label_of[s])]


def task(spec: str) -> Any:
    f = parse(spec)
    return make_sta(to_dta(f), bind_distributions(f), 1e-6)


def search(world: Table, sta: Any) -> tuple[list[Any], list[list[Any]]]:
    """The product by a breadth-first search over a FIFO of (world state, automaton
    state) pairs, the automaton's accepting and rejecting states kept as the two names
    ``"T"`` and ``"S"``: the states in the order found, and each state's choices as
    (action name or None, [(successor's number, probability summed in order)])."""
    dta = sta.dta

    def name(s: int, q: int) -> Any:
        return "T" if q == dta.accepting else "S" if q == dta.rejecting else (s, q)

    found = [name(world.initial, dta.step(dta.initial, world.propositions(world.initial)))]
    number = {found[0]: 0}
    choices: list[list[Any]] = []
    for here in found:  # the list grows as the search goes
        if here in ("T", "S"):
            choices.append([(None, [(number[here], 1.0)])])
            continue
        s, q = here
        out = []
        for a in world.actions(s):
            sums: dict[int, float] = {}
            for s2, p in world.successors(s, a, frozenset()):
                there = name(s2, dta.step(q, world.propositions(s2)))
                if there not in number:
                    number[there] = len(found)
                    found.append(there)
                j = number[there]
                sums[j] = sums[j] + p if j in sums else p
            out.append((a, list(sums.items())))
        choices.append(out)
    return found, choices


def compiled_product(world: Table, sta: Any, monkeypatch: pytest.MonkeyPatch,
                     paid: bool = True, **kw: Any) -> tuple[Any, int]:
    """The product with every level after the first by the compiled loop (``paid``: its
    load counted as paid), and how many of its calls expanded states."""
    from mitld_lp.util import kernel_loader

    ran = [0]
    real = tl.run_compiled

    def counted(*a: Any) -> Any:
        got = real(*a)
        ran[0] += got is not None
        return got

    monkeypatch.setattr(tl, "COMPILED", True)
    if paid:
        monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: True)
    monkeypatch.setattr(build, "run_compiled", counted)
    return product(world, sta, **kw), ran[0]


def numpy_product(world: Table, sta: Any, monkeypatch: pytest.MonkeyPatch) -> Any:
    monkeypatch.setattr(tl, "COMPILED", False)
    try:
        return product(world, sta)
    finally:
        monkeypatch.setattr(tl, "COMPILED", True)


def assert_same(a: Any, b: Any) -> None:
    assert a.action_names == b.action_names and a.initial == b.initial
    for name in ("row_groups", "choice_actions", "target", "sink", "truncated"):
        npt.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    npt.assert_array_equal(a.matrix.indptr, b.matrix.indptr)
    npt.assert_array_equal(a.matrix.indices, b.matrix.indices)
    assert a.matrix.data.tobytes() == b.matrix.data.tobytes()  # to the bit
    npt.assert_array_equal(a.states._keys, b.states._keys)


def assert_searched(mdp: Any, world: Table, sta: Any) -> None:
    found, choices = search(world, sta)
    assert mdp.n_states == len(found)
    for i, here in enumerate(found):
        rec = mdp.states[i]
        if here in ("T", "S"):
            assert str(rec) == ("target" if here == "T" else "sink")
        else:
            assert (rec.game, rec.automaton) == here
        lo, hi = int(mdp.row_groups[i]), int(mdp.row_groups[i + 1])
        assert hi - lo == len(choices[i])
        for c, (a, entries) in zip(range(lo, hi), choices[i], strict=True):
            aid = int(mdp.choice_actions[c])
            assert (aid < 0) if a is None else mdp.action_names[aid] == a
            b0, b1 = int(mdp.matrix.indptr[c]), int(mdp.matrix.indptr[c + 1])
            assert mdp.matrix.indices[b0:b1].tolist() == [j for j, _ in entries]
            assert mdp.matrix.data[b0:b1].tolist() == [p for _, p in entries]


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("spec", SPECS)
def test_the_compiled_levels_build_numpys_product_and_the_searched_one(
        seed: int, spec: str, monkeypatch: pytest.MonkeyPatch) -> None:
    world = Table(seed, 40 + 37 * seed, repeat=seed % 2 == 1)
    sta = task(spec)
    mdp, ran = compiled_product(world, sta, monkeypatch)
    if mdp.n_states > 8:
        assert ran > 0
    assert_same(mdp, numpy_product(world, sta, monkeypatch))
    assert_searched(mdp, world, sta)


@pytest.mark.parametrize("spec", ["F goal", "(F[0,7] goal) & F mid", "F (mid & F[0,3] goal)"])
def test_stopped_and_resumed_at_every_edge(spec: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Room for a handful of entries and new states per call: the loop stops before a
    state that might not fit and the next call goes on from there (a call that cannot
    expand a state leaves it to a batch of NumPy's)."""
    world = Table(4, 300, repeat=True)
    sta = task(spec)
    expected = numpy_product(world, sta, monkeypatch)
    # a state has at most 15 entries: 16 fit one, 5 leave some to NumPy's batches
    for entries, states, calls in ((16, 1 << 18, 10), (1 << 16, 16, 10), (5, 2, 0)):
        monkeypatch.setattr(tl, "_MIN_ENTRIES", entries)
        monkeypatch.setattr(tl, "_MAX_ENTRIES", entries)
        monkeypatch.setattr(tl, "_CHUNK_STATES", states)
        mdp, ran = compiled_product(world, sta, monkeypatch)
        assert ran >= calls
        assert_same(mdp, expected)


def test_switched_to_after_numpys_batches(monkeypatch: pytest.MonkeyPatch) -> None:
    """Unpaid and small, the loop takes over once NumPy's batches so far say the levels
    left pay for its load."""
    from mitld_lp.util import kernel_loader

    world = Table(4, 400, repeat=False)
    sta = task("(F[0,7] goal) & F mid")
    expected = numpy_product(world, sta, monkeypatch)
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: False)
    monkeypatch.setattr(tl, "loop_cached", lambda: True)  # the warm rule's constants
    monkeypatch.setattr(tl, "LOAD_SHARE", float("inf"))  # the load's memory no matter
    monkeypatch.setattr(tl, "COMPILED_MIN_STATES", 0)
    mdp, ran = compiled_product(world, sta, monkeypatch, paid=False)  # from the first level
    assert ran > 0
    assert_same(mdp, expected)
    monkeypatch.setattr(tl, "COMPILED_MIN_STATES", 10**9)
    calls = []  # NumPy's lean batches, by the number of states in each
    monkeypatch.setattr(tl.Plain, "expand", lambda self, keys, intern, real=tl.Plain.expand:
                        calls.append(keys.size) or real(self, keys, intern))
    monkeypatch.setattr(tl, "LOAD_SECONDS", 1e-9)  # any levels left pay for it
    monkeypatch.setattr(tl, "_SEEN", 2)
    mdp = product(world, sta)
    assert len(calls) == tl._SEEN  # the frontier's width seen, then the loop
    assert_same(mdp, expected)
    monkeypatch.setattr(tl, "LOAD_SECONDS", 1e9)  # no levels pay for it
    calls.clear()
    assert_same(product(world, sta), expected)
    assert len(calls) > tl._SEEN  # no switch: every level NumPy's


def test_the_state_budget_under_the_compiled_loop(monkeypatch: pytest.MonkeyPatch) -> None:
    world = Table(3, 250, repeat=False)
    sta = task("F goal")
    n = numpy_product(world, sta, monkeypatch).n_states
    assert n > 40
    monkeypatch.setattr(tl, "_CHUNK_STATES", 16)
    with pytest.raises(ProductTooLarge):
        compiled_product(world, sta, monkeypatch, max_states=n - 1)
    mdp, ran = compiled_product(world, sta, monkeypatch, max_states=n)
    assert mdp.n_states == n and ran > 0

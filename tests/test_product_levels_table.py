"""A plain table world's levels built in few NumPy calls (:mod:`mitld_lp.product.table_levels`):
the product is the one every level's general expansion builds, bit for bit, and the one a
breadth-first search written here state by state (a dict per row) builds, on random table
worlds and a PRISM program, for bounded, unbounded and safety tasks."""

from __future__ import annotations

import importlib.util
from collections.abc import Hashable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mitld_lp.automata.sta import make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.logic.parser import parse
from mitld_lp.mdp import ABSORB
from mitld_lp.model import bind_distributions
from mitld_lp.product import ProductTooLarge, build, product
from mitld_lp.product import table_levels as tl
from mitld_lp.product.states import Absorbing, ProductState
from mitld_lp.worlds.table import WorldTable

SPECS = [
    "F goal",                     # unbounded
    "F[0,4] goal",                # bounded: the automaton counts the steps
    "!bad U goal",                # with safety: a bad state is a sink
    "G !bad",                     # safety alone
    "(F[0,6] goal) & F mid",
]


class TableWorld:
    """A world given as arrays: its table, and the same moves through the game protocol."""

    ignores_events = True
    event_names: frozenset[str] = frozenset()

    def __init__(self, rng: np.random.Generator, n: int, *, repeat: bool) -> None:
        self.n_states = n
        self.states = tuple(f"s{i}" for i in range(n))
        self.initial = self.states[0]
        names = ("goal", "bad", "mid")
        self.proposition_names = frozenset(names)
        labels = [frozenset(), frozenset({"goal"}), frozenset({"bad"}), frozenset({"mid"}),
                  frozenset({"goal", "mid"})]
        label_of = rng.choice(len(labels), size=n, p=[0.8, 0.03, 0.05, 0.1, 0.02])
        label_of[0] = 0
        choices, action_of, branches, targets, probs = [0], [], [0], [], []
        self.acts = ("a", "b", "c")
        for s in range(n):
            k = int(rng.integers(1, 4))
            for a in rng.choice(3, size=k, replace=False).tolist():
                m = int(rng.integers(1, 5))
                # a thin frontier: successors mostly near s, so there are many levels
                t = (s + rng.integers(-2, 4, size=m)) % n
                if not repeat:
                    t = np.unique(t)
                w = rng.random(t.size) + 0.05
                targets.extend(t.tolist())
                probs.extend((w / w.sum()).tolist())
                branches.append(len(targets))
                action_of.append(a)
            choices.append(len(action_of))
        self.table = WorldTable(
            states=self.states, initial=0, label_sets=tuple(labels),
            label_of=label_of.astype(np.int64), choices=np.array(choices, dtype=np.int64),
            action_names=self.acts, action_of=np.array(action_of, dtype=np.int32),
            branches=np.array(branches, dtype=np.int64), targets=np.array(targets, dtype=np.int64),
            probabilities=np.array(probs, dtype=np.float64), checked=False,
        )

    def as_table(self) -> WorldTable:
        return self.table

    def _choices(self, s: Hashable) -> range:
        i = self.states.index(s)
        return range(int(self.table.choices[i]), int(self.table.choices[i + 1]))

    def actions(self, s: Hashable) -> tuple[str, ...]:
        return tuple(self.acts[int(self.table.action_of[c])] for c in self._choices(s))

    def successors(self, s: Hashable, a: str, events: frozenset[str]) -> Any:
        t = self.table
        for c in self._choices(s):
            if self.acts[int(t.action_of[c])] == a:
                lo, hi = int(t.branches[c]), int(t.branches[c + 1])
                return tuple((self.states[int(t.targets[j])], float(t.probabilities[j]))
                             for j in range(lo, hi))
        raise KeyError(a)

    def propositions(self, s: Hashable) -> frozenset[str]:
        t = self.table
        return t.label_sets[int(t.label_of[self.states.index(s)])]


def task(spec: str) -> Any:
    f = parse(spec)
    return make_sta(to_dta(f), bind_distributions(f), 1e-6)


def brute(world: Any, sta: Any) -> tuple[list[Any], list[list[tuple[str, dict[Any, float]]]]]:
    """The product by a plain breadth-first search: the states in the order found, and
    per state its choices (action, successors summed in the order they come)."""
    dta = sta.dta

    def node(s: Hashable, q: int) -> Any:
        if q == dta.accepting:
            return Absorbing.TARGET
        if q == dta.rejecting:
            return Absorbing.SINK
        return (s, q)

    s0 = world.initial
    order = [node(s0, dta.step(dta.initial, world.propositions(s0)))]
    seen = {order[0]: 0}
    rows = []
    head = 0
    while head < len(order):
        here = order[head]
        head += 1
        if isinstance(here, Absorbing):
            rows.append([("absorb", {here: 1.0})])
            continue
        s, q = here
        mine = []
        for a in world.actions(s):
            row: dict[Any, float] = {}
            for s2, p in world.successors(s, a, frozenset()):
                d = node(s2, dta.step(q, world.propositions(s2)))
                row[d] = row.get(d, 0.0) + p
                if d not in seen:
                    seen[d] = len(order)
                    order.append(d)
            mine.append((a, row))
        rows.append(mine)
    return order, rows


def same_as_brute(mdp: Any, world: Any, sta: Any) -> None:
    order, rows = brute(world, sta)
    assert mdp.n_states == len(order)
    at = {d: i for i, d in enumerate(order)}
    m = mdp.matrix
    for i, d in enumerate(order):
        rec = mdp.states[i]
        if isinstance(d, Absorbing):
            assert rec == d
        else:
            assert isinstance(rec, ProductState) and (rec.game, rec.automaton) == d
        lo, hi = int(mdp.row_groups[i]), int(mdp.row_groups[i + 1])
        assert hi - lo == len(rows[i])
        for c, (a, row) in zip(range(lo, hi), rows[i], strict=True):
            aid = int(mdp.choice_actions[c])
            assert (aid == ABSORB) if a == "absorb" else mdp.action_names[aid] == a
            b0, b1 = int(m.indptr[c]), int(m.indptr[c + 1])
            assert m.indices[b0:b1].tolist() == [at[x] for x in row]
            assert m.data[b0:b1].tobytes() == np.array(list(row.values())).tobytes()


def same_mdp(a: Any, b: Any) -> None:
    assert a.action_names == b.action_names and a.initial == b.initial
    for name in ("row_groups", "choice_actions", "target", "sink", "truncated"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert np.array_equal(a.matrix.indptr, b.matrix.indptr)
    assert np.array_equal(a.matrix.indices, b.matrix.indices)
    assert a.matrix.data.tobytes() == b.matrix.data.tobytes()
    assert np.array_equal(a.states._keys, b.states._keys)


def both(world: Any, sta: Any, monkeypatch: pytest.MonkeyPatch, **kw: Any) -> tuple[Any, Any, int]:
    """The product by the lean levels and by the general one; the levels built lean."""
    calls = [0]
    real = tl.Plain.expand

    def counted(self: Any, *a: Any) -> Any:
        calls[0] += 1
        return real(self, *a)

    monkeypatch.setattr(tl.Plain, "expand", counted)
    monkeypatch.setattr(tl, "COMPILED", False)  # NumPy's lean levels (the compiled loop:
    lean = product(world, sta, **kw)            # tests/test_product_bfs_kernels.py)
    monkeypatch.setattr(tl, "COMPILED", True)
    monkeypatch.setattr(build, "LEAN_TABLES", False)
    old = product(world, sta, **kw)
    monkeypatch.setattr(build, "LEAN_TABLES", True)
    return lean, old, calls[0]


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("spec", SPECS)
def test_lean_levels_build_the_general_product_and_the_brute_force_one(
    seed: int, spec: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    rng = np.random.default_rng(seed)
    world = TableWorld(rng, int(rng.integers(30, 120)), repeat=seed % 2 == 1)
    sta = task(spec)
    lean, old, levels = both(world, sta, monkeypatch)
    same_mdp(lean, old)
    same_as_brute(lean, world, sta)
    if lean.n_states > 8:  # more than one level: the lean path built some
        assert levels > 0


def test_rows_that_name_a_state_twice_are_merged_in_order(monkeypatch: pytest.MonkeyPatch) -> None:
    world = TableWorld(np.random.default_rng(11), 60, repeat=True)
    assert not tl._rows_distinct(world.table.targets, world.table.branches)
    sta = task("F goal")
    lean, old, _ = both(world, sta, monkeypatch)
    same_mdp(lean, old)
    same_as_brute(lean, world, sta)


def test_rows_distinct_is_false_only_where_a_row_may_repeat() -> None:
    br = np.array([0, 2, 4, 5])
    assert tl._rows_distinct(np.array([1, 3, 0, 2, 2]), br)      # a row ends high
    assert not tl._rows_distinct(np.array([1, 1, 0, 2, 2]), br)  # a row repeats 1
    assert not tl._rows_distinct(np.array([3, 1, 0, 2, 2]), br)  # unsorted: may repeat


def test_the_state_budget_is_checked_on_the_lean_path(monkeypatch: pytest.MonkeyPatch) -> None:
    world = TableWorld(np.random.default_rng(3), 200, repeat=False)
    sta = task("F goal")
    n = product(world, sta).n_states
    assert n > 40
    for flag in (True, False):
        monkeypatch.setattr(build, "LEAN_TABLES", flag)
        with pytest.raises(ProductTooLarge):
            product(world, sta, max_states=n - 1)
        assert product(world, sta, max_states=n).n_states == n


def test_plain_table_declines_events_and_worlds_without_a_table() -> None:
    from mitld_lp.product.layers import Layers
    from mitld_lp.worlds.task import check_alphabet

    world = TableWorld(np.random.default_rng(0), 20, repeat=False)
    for spec, plain in (("F goal", True), ("F (mid & D[geometric(0.4)] bell)", False)):
        sta = task(spec)
        f = Layers(world, check_alphabet(world, sta.dta.atoms, sta.events), sta)
        f.ensure_outcomes(np.array([f.situation(sta.events, 0)]))
        assert tl.plain_table(f) is plain


STORM = importlib.util.find_spec("stormpy") is not None
ROBOT = """mdp
module robot
  x : [0..6] init 0;
  [go] x<6 -> 0.6 : (x'=x+1) + 0.3 : true + 0.1 : (x'=max(x-1,0));
  [jump] x=1 -> 0.5 : (x'=4) + 0.5 : (x'=0);
  [back] x>0 -> 0.9 : (x'=x-1) + 0.1 : true;
endmodule
label "goal" = x=6;
label "mid" = x=3;
label "bad" = x=5;
"""


@pytest.mark.skipif(not STORM, reason="needs stormpy")
@pytest.mark.parametrize("spec", SPECS)
def test_a_prism_program_lean_general_and_brute(
    tmp_path: Path, spec: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    from mitld_lp.worlds.prism import load_prism

    p = tmp_path / "m.prism"
    p.write_text(ROBOT)
    game = load_prism(p)
    sta = task(spec)
    lean, old, _ = both(game, sta, monkeypatch)
    same_mdp(lean, old)
    same_as_brute(lean, game, sta)


@pytest.mark.parametrize("spec", ["F[0,4] goal", "!bad U goal"])
def test_steps_asked_level_by_level_when_not_tabulated(
    spec: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(tl, "_MAX_STEPS", 0)  # too many (automaton state, label) pairs
    world = TableWorld(np.random.default_rng(4), 90, repeat=False)
    sta = task(spec)
    lean, old, levels = both(world, sta, monkeypatch)
    assert levels > 0
    same_mdp(lean, old)
    same_as_brute(lean, world, sta)

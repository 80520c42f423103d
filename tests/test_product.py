"""Independent checks of the product construction (``mitld_lp.product``).

The reference is a brute-force product written here from the paper's definitions (the
STA's four cases, the product MDP of Section III-C) with this package's corrections (the hazard
instead of the pmf; events never at step 0; the automaton reads the step-0 label first):

* the grid moves are recomputed here (intended cell ``1 - 2 slip``, each perpendicular
  ``slip``, bounce off the walls);
* every external event keeps its own age, as the paper does (a tuple of ages, ``None``
  once the event has happened), saturated at ``AGE_CAP`` beyond which every hazard used
  is constant (checked);
* the hazards are computed from the masses by hand;
* the automaton is tracked as an *obligation* by :func:`progress` (not by the DTA's
  minimised table); an obligation is matched to the DTA state with the same language
  by a pairwise exploration of the two automata (exact, all lengths), and exactly one
  DTA state must match (minimality).

The two MDPs are compared by a bisimulation walk (paired states must have the same
game state, automaton language and pending set, and the same successor distribution
aggregated by that image) and by their optimal reach values, computed by a value
iteration written here.
"""

from __future__ import annotations

import itertools
import math
import re
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.automata.sta import make_sta
from mitld_lp.automata.translate import progress as _progress
from mitld_lp.automata.translate import to_dta
from mitld_lp.distributions import geometric, pmf
from mitld_lp.logic import parse
from mitld_lp.logic.syntax import FALSE, TRUE
from mitld_lp.model import load_model
from mitld_lp.product import (
    BYTES_PER_STATE,
    BYTES_PER_TRANSITION,
    ProductState,
    ProductTooLarge,
    default_max_memory,
    estimate_size,
    product,
)
from mitld_lp.testing import reference_product
from mitld_lp.worlds.grid import GridWorld

MODELS = Path(__file__).resolve().parent.parent / "models"
PAPER = "(D[mu1] b1 & F(b1 & F[0,3] A)) | (D[mu2] b2 & F(b2 & F[0,3] B))"
AGE_CAP = 8
E = frozenset
_PROGRESS: dict = {}


def progress(ob, letter):
    """:func:`mitld_lp.automata.translate.progress`, memoised for speed."""
    key = (ob, letter)
    if key not in _PROGRESS:
        _PROGRESS[key] = _progress(ob, letter)
    return _PROGRESS[key]


# --------------------------------------------------------------------------- value iteration


def value_iteration(matrix, row_groups, target, tol=1e-14, max_iter=200_000) -> np.ndarray:
    """Max reach probability of ``target`` (from below, Jacobi, until the update is
    below ``tol``)."""
    matrix = sp.csr_array(matrix)
    starts = np.asarray(row_groups[:-1])
    v = target.astype(float)
    for _ in range(max_iter):
        new = np.maximum.reduceat(matrix @ v, starts)
        new[target] = 1.0
        if np.max(np.abs(new - v)) < tol:
            return new
        v = new
    raise AssertionError("value iteration did not converge")


def product_value(mdp) -> float:
    return float(value_iteration(mdp.matrix, mdp.row_groups, np.asarray(mdp.target))[mdp.initial])


# --------------------------------------------------------------------------- brute force


def grid_moves(width, height, slip):
    deltas = {"N": (0, 1), "S": (0, -1), "E": (1, 0), "W": (-1, 0)}
    side = {"N": "EW", "S": "EW", "E": "NS", "W": "NS"}
    moves = {}
    for x, y in itertools.product(range(width), range(height)):
        for a in "NSEW":
            dist: dict = {}
            for d, p in [(a, 1 - 2 * slip), (side[a][0], slip), (side[a][1], slip)]:
                nx, ny = x + deltas[d][0], y + deltas[d][1]
                if not (0 <= nx < width and 0 <= ny < height):
                    nx, ny = x, y
                if p > 0:
                    dist[nx, ny] = dist.get((nx, ny), 0.0) + p
            moves[(x, y), a] = dist
    return moves


def hazard_table(masses, never=0.0):
    """h(k) for k = 1..len(masses)+AGE_CAP+2 from the masses (tail sums)."""
    n = len(masses) + AGE_CAP + 2
    m = list(masses) + [0.0] * (n - len(masses))
    out = {}
    for k in range(1, n + 1):
        alive = never + math.fsum(m[k - 1 :])
        out[k] = 1.0 if alive <= 0 else m[k - 1] / alive
    return out


def geometric_hazard(p):
    return {k: p for k in range(1, AGE_CAP + 40)}


class BruteForce:
    """The product MDP from the definitions, states as plain tuples."""

    def __init__(self, dta, moves, labels, start, hazards, truncation=None):
        self.dta = dta
        self.moves = moves
        self.labels = labels
        self.events = tuple(sorted(hazards))
        self.hazards = hazards
        self.truncation = truncation or {}
        for h in hazards.values():  # saturating the ages at AGE_CAP is exact
            assert all(h[k] == h[AGE_CAP + 1] for k in h if k > AGE_CAP)
        ob = progress(dta.formula, labels.get(start, E()))  # step 0: no events
        self.initial = self._close(start, ob, tuple(0 for _ in self.events))
        self.actions = sorted({a for _, a in moves})

    @staticmethod
    def _close(s, ob, ages):
        if ob == TRUE:
            return "target"
        if ob == FALSE:
            return "sink"
        return (s, ob, ages)

    def successors(self, state, action):
        s, ob, ages = state
        pending = [e for e, age in zip(self.events, ages, strict=True) if age is not None]
        out: dict = {}
        for r in range(len(pending) + 1):
            for happened in itertools.combinations(pending, r):
                p_e = 1.0
                for e, age in zip(self.events, ages, strict=True):
                    if age is None:
                        continue  # case 1: events that have happened do not count
                    h = self.hazards[e][age + 1]
                    p_e *= h if e in happened else 1.0 - h
                if p_e == 0.0:
                    continue
                new_ages = tuple(
                    None if age is None or e in happened else min(age + 1, AGE_CAP)
                    for e, age in zip(self.events, ages, strict=True)
                )
                if any(
                    age is not None
                    and e not in happened
                    and e in self.truncation
                    and age + 1 >= self.truncation[e]
                    for e, age in zip(self.events, ages, strict=True)
                ):
                    out["truncated"] = out.get("truncated", 0.0) + p_e
                    continue
                for s2, p_s in self.moves[s, action].items():
                    label = self.labels.get(s2, E()) | E(happened)
                    nxt = self._close(s2, progress(ob, label), new_ages)
                    out[nxt] = out.get(nxt, 0.0) + p_e * p_s
        return out

    def explore(self):
        states, index, rows = [self.initial], {self.initial: 0}, {}
        head = 0
        while head < len(states):
            b = states[head]
            head += 1
            if isinstance(b, str):
                continue
            rows[b] = {}
            for a in self.actions:
                succ = self.successors(b, a)
                rows[b][a] = succ
                for b2 in succ:
                    if b2 not in index:
                        index[b2] = len(states)
                        states.append(b2)
        return states, index, rows

    def value(self) -> float:
        states, index, rows = self.explore()
        data, cols, indptr, groups = [], [], [0], [0]
        for b in states:
            if isinstance(b, str):
                choices = [{b: 1.0}]
            else:
                choices = [rows[b][a] for a in self.actions]
            for row in choices:
                for b2, p in row.items():
                    cols.append(index[b2])
                    data.append(p)
                indptr.append(len(cols))
            groups.append(groups[-1] + len(choices))
        n = len(states)
        matrix = sp.csr_array((data, cols, indptr), shape=(groups[-1], n))
        target = np.array([b == "target" for b in states])
        return float(value_iteration(matrix, np.array(groups), target)[0])


class Matcher:
    """Maps an obligation to the DTA state with the same language (exactly one)."""

    def __init__(self, dta):
        self.dta = dta
        atoms = sorted(dta.atoms)
        self.letters = [
            E(c) for r in range(len(atoms) + 1) for c in itertools.combinations(atoms, r)
        ]
        self.cache: dict = {}

    def same_language(self, ob, q) -> bool:
        seen, stack = set(), [(ob, q)]
        while stack:
            o, s = stack.pop()
            if (o, s) in seen:
                continue
            seen.add((o, s))
            if (o == TRUE) != self.dta.is_accepting(s):
                return False
            stack.extend((progress(o, x), self.dta.step(s, x)) for x in self.letters)
        return True

    def __call__(self, ob) -> int:
        if ob not in self.cache:
            hits = [q for q in range(self.dta.n_states) if self.same_language(ob, q)]
            assert len(hits) == 1, (ob, hits)
            self.cache[ob] = hits[0]
        return self.cache[ob]


def brute_key(b, brute: BruteForce, match: Matcher):
    if isinstance(b, str):
        return b
    s, ob, ages = b
    q = match(ob)
    if q == brute.dta.rejecting:
        return "sink"
    pending = E(e for e, age in zip(brute.events, ages, strict=True) if age is not None)
    return (s, q, pending)


def product_key(key):
    if isinstance(key, str):
        return key
    assert isinstance(key, ProductState)
    return (key.game, key.automaton, key.pending)


def assert_bisimilar(mdp, brute: BruteForce) -> None:
    match = Matcher(brute.dta)
    _, _, rows = brute.explore()
    csr = sp.csr_array(mdp.matrix)
    indptr, indices, data = csr.indptr.tolist(), csr.indices.tolist(), csr.data.tolist()
    pairs = [(brute.initial, mdp.initial)]
    assert brute_key(brute.initial, brute, match) == product_key(mdp.states[mdp.initial])
    seen = set(pairs)
    matched_product: set[int] = set()
    head = 0
    while head < len(pairs):
        b, j = pairs[head]
        head += 1
        matched_product.add(j)
        key = mdp.states[j]
        if isinstance(key, str):
            assert brute_key(b, brute, match) == key
            c = mdp.row_groups[j]
            assert indices[indptr[c] : indptr[c + 1]] == [j]
            continue
        choices = {mdp.action_name(c): c for c in mdp.choices(j)}
        assert sorted(choices) == brute.actions
        for a, c in choices.items():
            lo, hi = indptr[c], indptr[c + 1]
            prod_row: dict = {}
            for col, p in zip(indices[lo:hi], data[lo:hi], strict=True):
                k = product_key(mdp.states[col])
                assert k not in prod_row, "two product successors with one image"
                prod_row[k] = (p, col)
            brute_row: dict = {}
            for b2, p in rows[b][a].items():
                k = brute_key(b2, brute, match)
                total, members = brute_row.get(k, (0.0, []))
                brute_row[k] = (total + p, [*members, b2])
            assert set(prod_row) == set(brute_row), (b, a)
            for k, (p, col) in prod_row.items():
                assert p == pytest.approx(brute_row[k][0], abs=1e-12), (b, a, k)
                for b2 in brute_row[k][1]:
                    if (b2, col) not in seen:
                        seen.add((b2, col))
                        pairs.append((b2, col))
    assert matched_product == set(range(mdp.n_states))  # every product state is matched


# --------------------------------------------------------------------------- the 2x2 example

GRID = {"A": [(1, 1)], "B": [(1, 0)]}
CASES = {
    "geometric": (
        {"b1": geometric(0.8), "b2": geometric(0.3)},
        {"b1": geometric_hazard(0.8), "b2": geometric_hazard(0.3)},
        {},
        None,
    ),
    "non-memoryless": (
        {"b1": geometric(0.8), "b2": pmf([0.1, 0.3, 0.4])},
        {"b1": geometric_hazard(0.8), "b2": hazard_table([0.1, 0.3, 0.4], never=0.2)},
        {},
        None,
    ),
    "finite support": (
        {"b1": pmf([0.0, 0.5, 0.5]), "b2": pmf([0.2, 0.2, 0.2, 0.4])},
        {"b1": hazard_table([0.0, 0.5, 0.5]), "b2": hazard_table([0.2, 0.2, 0.2, 0.4])},
        {},
        None,
    ),
    "truncated": (
        {"b1": geometric(0.5), "b2": geometric(0.3)},
        {"b1": geometric_hazard(0.5), "b2": geometric_hazard(0.3)},
        {"clock_reduction": False, "truncation": {"b1": 2, "b2": 3}},
        {"b1": 2, "b2": 3},
    ),
}


def _example(case):
    dists, hazards, kw, trunc = CASES[case]
    game = GridWorld.make(2, 2, start=(0, 0), slip=0.1, regions=GRID)
    dta = to_dta(parse(PAPER))
    sta = make_sta(dta, dists, 0.01, **kw)
    labels = {c: E(n for n, cells in GRID.items() if c in cells) for c in game.cells}
    brute = BruteForce(dta, grid_moves(2, 2, 0.1), labels, (0, 0), hazards, trunc)
    return product(game, sta), brute


@pytest.mark.parametrize("case", sorted(CASES))
def test_product_is_bisimilar_to_the_brute_force(case):
    mdp, brute = _example(case)
    assert_bisimilar(mdp, brute)


@pytest.mark.parametrize("case", sorted(CASES))
def test_product_value_equals_the_brute_force_value(case):
    mdp, brute = _example(case)
    v = product_value(mdp)
    assert 0.5 < v <= 1.0
    assert v == pytest.approx(brute.value(), abs=1e-9)


def test_truncated_values_bracket_the_exact_one():
    lower_mdp, _ = _example("truncated")
    # same events as "truncated" but exact (memoryless, no clock)
    game = GridWorld.make(2, 2, start=(0, 0), slip=0.1, regions=GRID)
    sta = make_sta(to_dta(parse(PAPER)), {"b1": geometric(0.5), "b2": geometric(0.3)}, 0.01)
    exact = product(game, sta)
    lo = product_value(lower_mdp)
    hi = float(
        value_iteration(
            lower_mdp.matrix,
            lower_mdp.row_groups,
            np.asarray(lower_mdp.target) | np.asarray(lower_mdp.truncated),
        )[lower_mdp.initial]
    )
    v = product_value(exact)
    assert lo <= v + 1e-12 and v <= hi + 1e-12
    assert np.asarray(lower_mdp.truncated).sum() == 1


# --------------------------------------------------------------------------- all models


@pytest.fixture(scope="module", params=sorted(p.name for p in MODELS.glob("*.toml")))
def model_product(request):
    m = load_model(MODELS / request.param)
    sta = make_sta(to_dta(m.spec), m.distributions, m.epsilon)
    return m, sta, product(m.game, sta)


def test_rows_are_distributions(model_product):
    _, _, mdp = model_product
    sums = np.asarray(mdp.matrix.sum(axis=1)).ravel()
    assert np.allclose(sums, 1.0, atol=1e-12)
    assert (mdp.matrix.data > 0).all() and (mdp.matrix.data <= 1 + 1e-12).all()
    assert (np.diff(mdp.row_groups) >= 1).all()
    # the special states are single and absorbing
    for mask in (mdp.target, mdp.sink, mdp.truncated):
        idx = np.flatnonzero(mask)
        assert len(idx) <= 1
        for j in idx:
            assert mdp.matrix[[mdp.row_groups[j]], [j]].item() == 1.0


# --------------------------------------------------------------------------- bus_grid


def _bus(name="bus_grid.toml", **kw):
    m = load_model(MODELS / name)
    dta = to_dta(m.spec)
    sta = make_sta(dta, m.distributions, m.epsilon, **kw)
    return m, dta, product(m.game, sta)


def test_bus_grid_is_small_and_clock_free():
    m, dta, mdp = _bus()
    ordinary = [s for s in mdp.states if isinstance(s, ProductState)]
    # 16 cells x DTA states x 4 pending sets, plus target/sink/truncated
    assert len(ordinary) <= 16 * dta.n_states * 4
    assert mdp.n_states <= 16 * dta.n_states * 4 + 3
    assert all(s.clock == 0 for s in ordinary)  # both buses are geometric
    assert not np.asarray(mdp.truncated).any()


def test_bus_grid_without_clock_reduction_grows_with_truncation():
    counts = []
    for T in (3, 4, 5):
        _, _, mdp = _bus(clock_reduction=False, truncation={"b1": T, "b2": T})
        clocks = {s.clock for s in mdp.states if isinstance(s, ProductState)}
        assert max(clocks) == T - 1  # not happened by step T: truncated
        assert np.asarray(mdp.truncated).sum() == 1
        counts.append(mdp.n_states)
    assert counts[0] < counts[1] < counts[2]


@pytest.mark.parametrize(
    ("name", "storm"), [("bus_grid.toml", 0.9244053), ("bus_grid_case2.toml", 0.9138372)]
)
def test_bus_grid_value_matches_storm(name, storm):
    _, _, mdp = _bus(name)
    assert product_value(mdp) == pytest.approx(storm, abs=1e-6)


# --------------------------------------------------------------------------- limits and edge cases


def test_max_states_exceeded():
    m = load_model(MODELS / "bus_grid.toml")
    sta = make_sta(to_dta(m.spec), m.distributions, m.epsilon)
    with pytest.raises(ProductTooLarge) as err:
        product(m.game, sta, max_states=50)
    assert re.search(r"\b50\b", str(err.value))


def test_formula_true_at_step_zero_gives_an_initial_target():
    game = GridWorld.make(2, 2, start=(1, 1), slip=0.1, regions={"A": [(1, 1)]})
    sta = make_sta(to_dta(parse("A")), {}, 0.01)
    mdp = product(game, sta)
    assert mdp.states[mdp.initial] == "target"
    assert bool(mdp.target[mdp.initial])
    assert mdp.n_states == 1
    # and with an event in the spec that is already satisfied at step 0
    sta = make_sta(to_dta(parse("A | D[mu] b")), {"b": geometric(0.5)}, 0.01)
    mdp = product(game, sta)
    assert bool(mdp.target[mdp.initial])


def test_formula_false_at_step_zero_gives_an_initial_sink():
    game = GridWorld.make(2, 2, start=(0, 0), slip=0.1, regions={"A": [(1, 1)]})
    mdp = product(game, make_sta(to_dta(parse("A & F[0,3] A")), {}, 0.01))
    assert bool(mdp.sink[mdp.initial])
    assert product_value(mdp) == 0.0


# --------------------------------------------------------------------------- the array build


def assert_same_mdp(a, b) -> None:
    """Equal state for state, in the same order, and bit for bit in every array."""
    assert a.n_states == b.n_states and a.initial == b.initial
    assert list(a.states) == list(b.states)
    assert a.action_names == b.action_names
    for name in ("row_groups", "choice_actions", "target", "sink", "truncated"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    for name in ("indptr", "indices", "data"):
        assert np.array_equal(getattr(a.matrix, name), getattr(b.matrix, name)), name


@pytest.mark.parametrize("name", sorted(p.name for p in MODELS.glob("*.toml")))
def test_array_build_equals_the_state_at_a_time_build_on_the_models(name):
    m = load_model(MODELS / name)
    sta = make_sta(to_dta(m.spec), m.distributions, m.epsilon)
    assert_same_mdp(product(m.game, sta), reference_product(m.game, sta))


@pytest.mark.parametrize("case", sorted(CASES))
def test_array_build_equals_the_state_at_a_time_build_on_the_example(case):
    dists, _, kw, _ = CASES[case]
    game = GridWorld.make(2, 2, start=(0, 0), slip=0.1, regions=GRID)
    sta = make_sta(to_dta(parse(PAPER)), dists, 0.01, **kw)
    assert_same_mdp(product(game, sta), reference_product(game, sta))


RANDOM_SPECS = (
    ("D[mu1] e1 & F(e1 & F[0,2] A)", {"e1": pmf([0.2, 0.5, 0.3])}),
    ("(D[mu1] e1 & F(e1 & F[0,3] A)) | (D[mu2] e2 & F[1,4] (e2 & B))",
     {"e1": geometric(0.4), "e2": pmf([0.1, 0.3, 0.2, 0.4])}),
    ("!B U[0,5] (A & (D[mu1] e1 & F e1))", {"e1": pmf([0.5, 0.25])}),
    ("F[0,4] A & G[0,3] !B", {}),
)


def _random_game(rng: np.random.Generator, events: list[str]):
    from mitld_lp.worlds.game import ExplicitGame

    n = int(rng.integers(2, 9))
    names = ["a", "b", "c"]

    def dist():
        k = int(rng.integers(1, min(n, 3) + 1))
        succ = rng.choice(n, size=k, replace=False)
        w = rng.random(k) + 0.05
        return {int(s): float(x) for s, x in zip(succ, w / w.sum(), strict=True)}

    transitions = {}
    for s in range(n):
        acts = list(rng.permutation(names)[: int(rng.integers(1, 4))])
        transitions[s] = {a: dist() for a in acts}
    labels = {s: {p for p in "AB" if rng.random() < 0.35} for s in range(n)}
    overrides = {}
    for s in range(n):
        for a in transitions[s]:
            if events and rng.random() < 0.4:
                happened = frozenset(e for e in events if rng.random() < 0.6)
                overrides[s, a, happened] = dist()
    return ExplicitGame(
        initial=0, transitions=transitions, labels=labels,
        proposition_names=frozenset("AB"), event_transitions=overrides,
    )


@pytest.mark.parametrize("seed", range(12))
def test_array_build_equals_the_state_at_a_time_build_on_random_games(seed):
    rng = np.random.default_rng(seed)
    text, dists = RANDOM_SPECS[seed % len(RANDOM_SPECS)]
    game = _random_game(rng, sorted(dists))
    kw = {"clock_reduction": False, "truncation": dict.fromkeys(dists, 3)} if seed % 3 == 0 else {}
    sta = make_sta(to_dta(parse(text)), dists, 0.01, **kw)
    mdp = product(game, sta)
    assert_same_mdp(mdp, reference_product(game, sta))
    # every record maps back to its index
    for i, s in enumerate(mdp.states):
        assert mdp.states.position(s) == i and mdp.states.index(s) == i and s in mdp.states
    stranger = ProductState(999, 0, frozenset(), 0)
    assert mdp.states.position(stranger) is None and stranger not in mdp.states
    with pytest.raises(ValueError, match="not a state"):
        mdp.states.index(stranger)


# --------------------------------------------------------------------------- budgets


def test_size_estimate_counts_the_factors():
    game = GridWorld.make(3, 3, obstacles=[(2, 2)], regions={"A": [(1, 1)]})
    dists = {"a": geometric(0.5), "b": pmf([0.2, 0.3, 0.5])}  # caps 0 and 2
    sta = make_sta(to_dta(parse("D[mu1] a & D[mu2] b & F(a & F[0,2] A) & F b")), dists, 0.01)
    # situations by enumeration: every pending set with clocks 0..max cap of the set
    caps = {"a": 0, "b": 2}
    situations = sum(
        max((caps[e] for e in pend), default=0) + 1
        for r in range(3) for pend in itertools.combinations("ab", r)
    )
    assert situations == 1 + 1 + 3 + 3
    est = estimate_size(game, sta)
    dta = sta.dta
    live = [q for q in range(dta.n_states) if not dta.is_accepting(q) and not dta.is_rejecting(q)]
    assert (est.game_states, est.automaton_states, est.situations) == (8, len(live), 8)
    assert est.states == 8 * len(live) * 8 + 3
    assert product(game, sta).n_states <= est.states


@pytest.mark.parametrize("seed", range(8))
def test_size_estimate_bounds_random_products(seed):
    rng = np.random.default_rng(100 + seed)
    text, dists = RANDOM_SPECS[seed % len(RANDOM_SPECS)]
    game = _random_game(rng, sorted(dists))
    sta = make_sta(to_dta(parse(text)), dists, 0.01)
    est = estimate_size(game, sta)
    assert est.game_states == len(game.transitions)
    assert product(game, sta).n_states <= est.states


def test_a_huge_grid_is_refused_at_the_state_budget_without_being_tabulated():
    import tracemalloc

    sta = make_sta(to_dta(parse("F[0,30] A")), {}, 0.01)
    tracemalloc.start()
    try:
        game = GridWorld.make(1000, 1000, start=(500, 500), regions={"A": [(0, 0)]})
        with pytest.raises(ProductTooLarge) as err:
            product(game, sta, max_states=1000)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20e6  # a tabulated 1000 x 1000 grid takes gigabytes
    text = str(err.value)
    assert "1,000 reachable states" in text and "1,000,000 game states" in text


def test_the_memory_budget_is_checked_before_the_states_are_stored():
    m = load_model(MODELS / "patrol.toml")
    sta = make_sta(to_dta(m.spec), m.distributions, m.epsilon)
    mdp = product(m.game, sta, max_memory=10**9)
    # the whole product at the measured rates, by hand
    need = mdp.n_states * BYTES_PER_STATE + mdp.n_transitions * BYTES_PER_TRANSITION
    assert need > 2_000_000
    with pytest.raises(ProductTooLarge, match=r"more than max_memory = 2\.0 MB") as err:
        product(m.game, sta, max_memory=2_000_000)
    found = int(re.search(r"\(([\d,]+) states found", str(err.value)).group(1).replace(",", ""))
    assert found < mdp.n_states


def test_default_memory_budget_is_half_the_machine():
    meminfo = Path("/proc/meminfo")
    if not meminfo.exists():
        pytest.skip("no /proc/meminfo to compare with")
    kb = int(re.search(r"MemTotal:\s+(\d+) kB", meminfo.read_text()).group(1))
    assert default_max_memory() == kb * 1024 // 2


@pytest.mark.parametrize("name", sorted(p.name for p in MODELS.glob("*.toml")))
def test_component_counts_from_codes_equal_the_counts_over_records(name):
    from dataclasses import replace

    from mitld_lp.product import component_counts

    m = load_model(MODELS / name)
    mdp = product(m.game, make_sta(to_dta(m.spec), m.distributions, m.epsilon))
    by_records = component_counts(replace(mdp, states=tuple(mdp.states)))
    assert component_counts(mdp) == by_records
    ordinary = [s for s in mdp.states if isinstance(s, ProductState)]
    assert by_records["clock_values"] == len({s.clock for s in ordinary})
    assert by_records["ordinary_states"] + 3 >= mdp.n_states


@pytest.mark.parametrize("seed", [1, 5])
def test_array_build_with_hashed_memos_equals_the_state_at_a_time_build(seed, monkeypatch):
    """Memos beyond the dense limit move to a hash index, and so does the index of the
    states found (forced here with a tiny limit)."""
    import importlib

    monkeypatch.setattr(importlib.import_module("mitld_lp.util.arrays"), "DENSE_LIMIT", 8)
    monkeypatch.setattr(importlib.import_module("mitld_lp.product.build"), "DENSE_LIMIT", 8)
    rng = np.random.default_rng(seed)
    text, dists = RANDOM_SPECS[seed % len(RANDOM_SPECS)]
    game = _random_game(rng, sorted(dists))
    sta = make_sta(to_dta(parse(text)), dists, 0.01)
    assert_same_mdp(product(game, sta), reference_product(game, sta))
    m = load_model(MODELS / "red_light.toml")
    sta = make_sta(to_dta(m.spec), m.distributions, m.epsilon)
    assert_same_mdp(product(m.game, sta), reference_product(m.game, sta))


def test_product_refuses_a_proposition_it_could_never_see():
    from mitld_lp import GridWorld, make_sta, parse, to_dta

    world = GridWorld.make(2, 1, start=(0, 0), regions={"A": [(1, 0)]})
    sta = make_sta(to_dta(parse("F[0,3] a")), {}, 0.01)
    with pytest.raises(ValueError, match=r"proposition 'a' is neither a proposition nor an event "
                       r"\(propositions: A; events: none\)"):
        product(world, sta)


def test_key_codec_numbers_every_triple_once_and_decodes_ints_and_arrays():
    from mitld_lp.product.states import KeyCodec

    codec = KeyCodec(n_q=5, n_sit=7)
    triples = [(g, q, s) for g in range(4) for q in range(5) for s in range(7)]
    keys = [codec.key(*t) for t in triples]
    assert sorted(keys) == list(range(4 * 5 * 7))  # a bijection onto 0 .. 139
    assert [codec.unkey(k) for k in keys] == triples
    g, q, s = (np.array(c) for c in zip(*triples, strict=True))
    back = codec.unkey(codec.key(g, q, s))
    assert all(np.array_equal(a, b) for a, b in zip(back, (g, q, s), strict=True))
    assert codec.fits((1 << 62) // 35) and not codec.fits((1 << 62) // 35 + 1)

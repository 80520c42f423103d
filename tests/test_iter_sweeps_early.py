"""The interval iteration's early jump on a compiled block (``solvers/early_jump.py``),
its cost forecast made on the block as swept (no moves out of it) with the sweeps' own
exit rewards, and the sweeps' gate (``sweep_gate.use_compiled``), against routes written
here: every state's exact optimum, the best over every memoryless deterministic policy
of its chain solved in fractions (small MDPs of dyadic probabilities, so the floats the
solver reads are the fractions exactly), the start policy and exit rewards recomputed on
the whole block as the iteration made them before, and the gate's rule from its
documented formula on grids, whose depth is known in closed form."""

from __future__ import annotations

import itertools
from collections import deque
from fractions import Fraction

import numpy as np
import pytest
from test_iter_rare_sweeps import fraction_mdp as rare_mdp
from test_sweep_gate_choice import gate_block

from mitld_lp.mdp import MDP
from mitld_lp.solvers import early_jump, iteration, jump_cost, kernels, sweep_gate
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.policy_jump import start_policy
from mitld_lp.testing.exact import chain_values

needs_numba = pytest.mark.skipif(kernels.compiled_kernel() is None,
                                 reason="numba is not installed")


# ------------------------------------------------------------------- small MDPs, exact
def _choices(seed: int, n: int) -> list[list[dict[int, Fraction]]]:
    """``n`` states of one or two choices each, every choice moving among the states with
    sixty-two sixty-fourths of its mass in cycles, one to the goal (``n``) and one to the
    goal or the fail state (``n + 1``): a block that drains slowly, so the compiled
    sweeps are still open when the early look reads them, its values inside (0, 1) in
    both senses."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        options = []
        for _c in range(int(rng.integers(1, 3))):
            succ = rng.choice(n, size=int(rng.integers(1, 4)), replace=False).tolist()
            parts = rng.multinomial(62, [1 / len(succ)] * len(succ))  # sums to 62
            option: dict[int, Fraction] = {}
            for t, k in zip(succ, parts, strict=True):
                if k:
                    option[t] = Fraction(int(k), 64)
            option[n] = Fraction(1, 64)  # the goal's share: no state's minimum is 0
            last = n if rng.random() < 0.5 else n + 1
            option[last] = option.get(last, Fraction(0)) + Fraction(1, 64)
            options.append({t: p for t, p in option.items() if p})
        out.append(options)
    return out


def _mdp(choices: list[list[dict[int, Fraction]]]) -> MDP:
    """The MDP of ``choices`` and two absorbing states after them, the goal and fail."""
    return rare_mdp(choices, len(choices) + 2)


def _policy_values(step: dict[int, dict[int, Fraction]], goal: int) -> dict[int, Fraction]:
    """Each state's probability of reaching ``goal`` in the chain ``step``: solved in
    fractions over the states that reach it (``chain_values``), the others 0."""
    good = {goal}
    grew = True
    while grew:
        grew = False
        for s, option in step.items():
            if s not in good and any(t in good for t in option):
                good.add(s)
                grew = True
    return chain_values(step, sorted(good - {goal}), goal)


def _exact(choices: list[list[dict[int, Fraction]]], sense: Sense) -> list[Fraction]:
    """Every state's optimum (``sense``) over the memoryless deterministic policies,
    each policy's chain solved exactly."""
    n = len(choices)
    best: list[Fraction | None] = [None] * n
    for policy in itertools.product(*(range(len(c)) for c in choices)):
        step = {s: choices[s][policy[s]] for s in range(n)}
        values = _policy_values(step, n)
        for s in range(n):
            v = values.get(s, Fraction(0))
            b = best[s]
            best[s] = v if b is None else (max(b, v) if sense is Sense.MAX else min(b, v))
    return [b if b is not None else Fraction(0) for b in best]


def _holds(lower: float, exact: Fraction, upper: float) -> bool:
    """``exact`` inside ``[lower, upper]`` widened by 4 units in the last place: the
    iteration's bounds are float sums rounded to nearest (the certificate stage makes a
    bracket strict), so an exact value can sit a rounding beyond a bound equal to it in
    float (a single state's exact formula, rounded to nearest)."""
    slack = 4
    return (Fraction(lower) - slack * Fraction(float(np.spacing(lower))) <= exact
            <= Fraction(upper) + slack * Fraction(float(np.spacing(upper))))


def _force_early(monkeypatch: pytest.MonkeyPatch, worth: bool) -> dict[str, int]:
    """Every compiled block looked at early (after 32 sweeps, plain sweeps without the
    guesses so the small blocks are still open there), the jump's cost forecast taken as
    ``worth`` it or not; the calls of ``_early_jump`` and ``whole`` counted."""
    monkeypatch.setattr(iteration, "_EARLY", (16, 16, 0))
    monkeypatch.setattr(iteration, "_COMPILED_SWEEPS_BEFORE_POLICY", 4096)
    monkeypatch.setattr(kernels, "OPTIMISTIC", False)
    monkeypatch.setattr(jump_cost, "worth", lambda c, saved: worth)
    calls = {"early": 0, "whole": 0}
    for module, name, key in ((iteration, "_early_jump", "early"),
                              (iteration, "whole", "whole"), (early_jump, "whole", "whole")):
        func = getattr(module, name)

        def counted(*args, _func=func, _key=key, **kwargs):
            calls[_key] += 1
            return _func(*args, **kwargs)

        monkeypatch.setattr(module, name, counted)
    return calls


@needs_numba
@pytest.mark.parametrize("worth", [True, False])
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(4))
def test_bracket_holds_the_exact_optimum_after_an_early_look(
        monkeypatch: pytest.MonkeyPatch, seed: int, sense: Sense, worth: bool) -> None:
    choices = _choices(seed, 7)
    mdp = _mdp(choices)
    calls = _force_early(monkeypatch, worth)
    res = iteration.interval_iteration(mdp, mdp.target, sense=sense, compiled=True,
                                       gap="max", precision=None, progress=False)
    assert calls["early"] >= 1  # the early look was taken
    if not worth:  # refused before the work: the block's moves out never made
        assert calls["whole"] == 0
    exact = _exact(choices, sense)
    for s, v in enumerate(exact):
        assert _holds(float(res.lower[s]), v, float(res.upper[s])), s
    assert float(np.max(res.upper - res.lower)) < 1e-9


@needs_numba
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_early_jump_forecast_reads_what_the_whole_block_gives(
        monkeypatch: pytest.MonkeyPatch, sense: Sense) -> None:
    # the forecast's exit rewards and start policy, taken from the sweeps' exits on the
    # block without its moves out, are those the whole block (Block.of of the quotient,
    # its own to_target + outer @ bounds) gives, bit for bit
    _force_early(monkeypatch, False)
    seen = []
    wanted: list[np.ndarray] = []
    plain = iteration._early_jump
    cost = jump_cost.cost

    def check(block, rewards, bounds, first, tol, precision, sense_, saved, exits, q):
        full = iteration.whole(q, block)
        own = 0 if sense_ is Sense.MAX else 1
        theirs = rewards[full.choices, own] + full.outer @ bounds[:, own]
        assert block.outer is None and full.outer is not None
        np.testing.assert_array_equal(np.asarray(exits[:, own]).view(np.int64),
                                      theirs.view(np.int64))
        wanted.append(start_policy(full, theirs, first[:, own], sense_))
        return plain(block, rewards, bounds, first, tol, precision, sense_, saved, exits, q)

    def forecast(block, chosen, saved=None):  # the start policy the forecast is made from
        np.testing.assert_array_equal(chosen, wanted[-1])
        seen.append(block.states.size)
        return cost(block, chosen, saved)

    monkeypatch.setattr(jump_cost, "cost", forecast)
    monkeypatch.setattr(iteration, "_early_jump", check)
    for seed in range(6):
        mdp = _mdp(_choices(100 + seed, 9))
        iteration.interval_iteration(mdp, mdp.target, sense=sense, compiled=True,
                                     gap="max", precision=None, progress=False)
    assert len(seen) >= 3


@needs_numba
@pytest.mark.parametrize("seed", range(3))
def test_compiled_and_numpy_routes_both_hold_the_exact_optimum(seed: int) -> None:
    # Gauss--Seidel (compiled) and Jacobi (NumPy) sweeps stop at different bits; each
    # bracket holds the exact optimum, and the two brackets overlap
    choices = _choices(200 + seed, 6)
    mdp = _mdp(choices)
    for sense in (Sense.MAX, Sense.MIN):
        exact = _exact(choices, sense)
        got = [iteration.interval_iteration(mdp, mdp.target, sense=sense, compiled=c,
                                            gap="max", progress=False)
               for c in (True, False)]
        for res in got:
            for s, v in enumerate(exact):
                assert _holds(float(res.lower[s]), v, float(res.upper[s])), (s, sense)


def test_reach_search_finds_the_states_the_state_graph_gives() -> None:
    # the iteration's search for the states the initial one reaches, on the quotient's
    # moves with their duplicates kept, against a breadth-first search written here
    from mitld_lp.solvers.quotient import reduce

    for seed in range(6):
        mdp = _mdp(_choices(300 + seed, 9))
        q = reduce(mdp, mdp.target)
        if q.n_states == 0 or q.initial < 0:
            continue
        graph = iteration._moves(q)
        from mitld_lp.util.traversal import breadth_first_order

        found = set(np.asarray(breadth_first_order(graph, q.initial)).tolist())
        succ = [set() for _ in range(q.n_states)]
        m = q.matrix
        for s in range(q.n_states):
            for c in range(int(q.row_groups[s]), int(q.row_groups[s + 1])):
                succ[s].update(int(t) for t in m.indices[m.indptr[c]:m.indptr[c + 1]])
        want, queue = {q.initial}, deque([q.initial])
        while queue:
            for t in succ[queue.popleft()]:
                if t not in want:
                    want.add(t)
                    queue.append(t)
        assert found == want


# ------------------------------------------------------------------------- the gate
def _forecast(n: int, nnz: int, depth: int, entries: int, loaded: bool,
              cheap: bool) -> bool:
    """The gate's documented rule (sweep_gate's module docs), its constants as written
    there, for a block of ``n`` states of one choice each, ``nnz`` entries and
    ``depth``: never in a product under 150,000 entries, always for a block of 150,000;
    else compiled where the block is deeper than the 100 Jacobi sweeps and its forecast
    work (16 + depth Gauss--Seidel sweeps, numba's load unless loaded: 2.3e6 entries by
    the loader, 5e7 by numba) is less than NumPy's (3 entries a Jacobi sweep's entry,
    100 sweeps, then the jump's 1 + depth / 11 rounds of 400 a state and 20 an entry)."""
    if entries < 150_000:
        return False
    if nnz >= 150_000:
        return True
    sweep = nnz + n
    numpy = 3.0 * min(depth, 100) * sweep
    if depth > 100:
        numpy += (1.0 + depth / 11.0) * (400.0 * n + 20.0 * nnz)
    load = 0.0 if loaded else (2.3e6 if cheap else 5.0e7)
    compiled = load + (16.0 + depth) * sweep
    return n > 100 and depth > 100 and compiled < numpy


def _grid(w: int, h: int) -> list[list[int]]:
    """A ``w x h`` grid's four-neighbour moves: ``2 ((w - 1) h + w (h - 1))`` entries."""
    return [[(x + dx) * h + y + dy for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1))
             if 0 <= x + dx < w and 0 <= y + dy < h]
            for x in range(w) for y in range(h)]


def _grid_rule(w: int, h: int, entries: int, loaded: bool, cheap: bool) -> bool:
    return _forecast(w * h, 2 * ((w - 1) * h + w * (h - 1)), w + h - 2, entries, loaded,
                     cheap)


def _boundary(w: int, loaded: bool, cheap: bool) -> int | None:
    """The least height from which a ``w``-wide grid is swept compiled by the rule
    (first past the depth of 100, then past the forecast's crossing), if below 40,000."""
    first = next((h for h in range(1, 200) if _grid_rule(w, h, 10**7, loaded, cheap)),
                 None)
    if first is not None:
        return first
    lo, hi = 200, 40_000  # the crossing, where the load is counted: bisected
    if not _grid_rule(w, hi, 10**7, loaded, cheap):
        return None
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if _grid_rule(w, mid, 10**7, loaded, cheap) else (mid, hi)
    return hi


@needs_numba
@pytest.mark.parametrize("loaded", [False, True])
@pytest.mark.parametrize("cheap", [False, True])
def test_gate_decides_as_its_rule_written_here(monkeypatch: pytest.MonkeyPatch,
                                               loaded: bool, cheap: bool) -> None:
    # grids either side of the rule's boundary (by height, one and two widths), where
    # any other constant would move it, and on both sides of the product's floor
    monkeypatch.setattr(sweep_gate, "_CHEAP", [cheap])
    monkeypatch.setattr(kernels, "kernel_loaded", lambda: loaded)
    picked = []
    for w in (1, 2):
        edge = _boundary(w, loaded, cheap)
        assert edge is not None
        for h in (edge - 1, edge, edge + 1, 101 - w + 1, 102 - w + 1):
            block = gate_block(_grid(w, h))
            assert jump_cost.block_depth(block) == w + h - 2  # the depth written here
            for entries in (149_999, 10**7):
                want = _grid_rule(w, h, entries, loaded, cheap)
                got = sweep_gate.use_compiled(entries, int(block.inner.nnz), block)
                assert got == want, (w, h, entries)
                picked.append(got)
    assert any(picked) and not all(picked)

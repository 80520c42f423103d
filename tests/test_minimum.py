"""A minimum solved as a minimum, and rare values to relative precision.

The references are independent of the solvers: every deterministic policy of a small
MDP evaluated in exact rational arithmetic (``fractions.Fraction``; memoryless
deterministic policies attain both optima of reachability), the graph's 0/1 sets read
off those exact optima, and Storm's exact engine (``stormpy.build_model[Rational]``) on
PRISM files written here.
"""

from __future__ import annotations

import importlib.util
import itertools
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from storm_exact import RARE, storm_rational

from mitld_lp import load_model, synthesize
from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.solvers import Layout, Status, evaluate_policy, interval_iteration, solve_lp
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.quotient import prob0_min, prob1_max, prob1_min
from mitld_lp.testing.exact import chain_values

needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy: pip install -e '.[prism]'")


# --------------------------------------------------------------------------- references


def _rows(mdp: MDP) -> list[list[dict[int, Fraction]]]:
    """Per state, per choice, the successor distribution as written: the stored floats
    as exact fractions, renormalised to sum 1 (so that 0 and 1 are exact)."""
    m = sp.csr_array(mdp.matrix)
    out = []
    for s in range(mdp.n_states):
        choices = []
        for c in range(int(mdp.row_groups[s]), int(mdp.row_groups[s + 1])):
            lo, hi = m.indptr[c], m.indptr[c + 1]
            dist = {int(t): Fraction(float(p)) for t, p in zip(m.indices[lo:hi], m.data[lo:hi],
                                                                strict=True) if p > 0}
            total = sum(dist.values())
            choices.append({t: p / total for t, p in dist.items()})
        out.append(choices)
    return out


def _chain_value(rows: list[list[dict[int, Fraction]]], pick: tuple[int, ...],
                 target: set[int]) -> list[Fraction]:
    """The exact probability of reaching ``target`` from every state under the policy
    ``pick`` (a choice index per state): Gauss-Jordan on the states that can reach it."""
    n = len(rows)
    succ = [rows[s][pick[s]] for s in range(n)]
    can = set(target)
    grew = True
    while grew:
        grew = False
        for s in range(n):
            if s not in can and any(t in can for t in succ[s]):
                can.add(s)
                grew = True
    solve = [s for s in range(n) if s in can and s not in target]
    solved = chain_values(succ, solve, target)
    value = [Fraction(1) if s in target else Fraction(0) for s in range(n)]
    for s, v in solved.items():
        value[s] = v
    return value


def brute_force(mdp: MDP, target: np.ndarray) -> tuple[list[Fraction], list[Fraction]]:
    """``(Pmin, Pmax)`` of every state: the least and greatest exact value over every
    deterministic memoryless policy."""
    rows = _rows(mdp)
    goal = {int(s) for s in np.flatnonzero(target)}
    best_min: list[Fraction] | None = None
    best_max: list[Fraction] | None = None
    for pick in itertools.product(*(range(len(r)) for r in rows)):
        v = _chain_value(rows, pick, goal)
        best_min = v if best_min is None else [min(a, b) for a, b in zip(best_min, v, strict=True)]
        best_max = v if best_max is None else [max(a, b) for a, b in zip(best_max, v, strict=True)]
    assert best_min is not None and best_max is not None
    return best_min, best_max


def small_mdp(seed: int, *, n: int = 7, rare: float = 1.0) -> MDP:
    """A random MDP of ``n`` states: the last is the target, the one before a sink;
    every other state has 1-3 choices of 1-3 successors (pure self-loops among them: end
    components); with ``rare`` < 1 every probability of entering the target is scaled
    by it (the rest of the row takes the difference), so values are powers of it."""
    rng = np.random.default_rng(seed)
    target, sink = n - 1, n - 2
    rows, cols, vals, groups, actions = [], [], [], [0], []
    for s in range(n):
        if s in (target, sink):
            k = 1
            dists = [{s: 1.0}]
        else:
            k = int(rng.integers(1, 4))
            dists = []
            for _ in range(k):
                if rng.random() < 0.15:
                    dists.append({s: 1.0})
                    continue
                succ = rng.choice(n, size=int(rng.integers(1, 4)), replace=False)
                w = rng.random(succ.size) + 0.05
                w = w / w.sum()
                d = {int(t): float(p) for t, p in zip(succ, w, strict=True)}
                if target in d and rare < 1.0 and len(d) > 1:
                    moved = d[target] * (1.0 - rare)
                    d[target] -= moved
                    other = next(t for t in d if t != target)
                    d[other] += moved
                dists.append(d)
        for d in dists:
            c = len(actions)
            actions.append(ABSORB if s in (target, sink) else len(actions) % 3)
            for t, p in d.items():
                rows.append(c)
                cols.append(t)
                vals.append(p)
        groups.append(len(actions))
    matrix = sp.csr_array((vals, (rows, cols)), shape=(len(actions), n))
    mask = np.zeros(n, dtype=bool)
    tmask, smask = mask.copy(), mask.copy()
    tmask[target] = True
    smask[sink] = True
    return MDP(matrix=matrix, row_groups=np.asarray(groups, dtype=np.int64),
               choice_actions=np.asarray(actions, dtype=np.int32),
               action_names=("a", "b", "c"), initial=0, target=tmask, sink=smask,
               truncated=mask, states=range(n))


def _within(got: float, exact: Fraction, rel: float) -> bool:
    return abs(Fraction(got) - exact) <= Fraction(rel) * exact


# --------------------------------------------------------------------------- the graph


@pytest.mark.parametrize("seed", range(12))
def test_qualitative_sets_are_the_exact_zeros_and_ones(seed: int) -> None:
    """Prob0A/Prob1E and Prob0E/Prob1A from the graph are exactly where the brute-force
    optima are 0 and 1, and every other optimum is strictly between."""
    mdp = small_mdp(seed)
    pmin, pmax = brute_force(mdp, mdp.target)
    for sense, exact in ((Sense.MAX, pmax), (Sense.MIN, pmin)):
        q = analyse(mdp, mdp.target, sense=sense)[0]
        decided = q.qualitative
        assert [bool(z) for z in decided.zero] == [v == 0 for v in exact], sense
        assert [bool(o) for o in decided.one] == [v == 1 for v in exact], sense
        assert [bool(z) for z in decided.unreachable] == [v == 0 for v in pmax], sense
    assert [bool(x) for x in prob0_min(mdp, mdp.target)] == [v == 0 for v in pmin]
    assert [bool(x) for x in prob1_min(mdp, mdp.target)] == [v == 1 for v in pmin]
    assert [bool(x) for x in prob1_max(mdp, mdp.target)] == [v == 1 for v in pmax]


@pytest.mark.parametrize("seed", range(6))
def test_truncated_models_share_one_minimum_quotient(seed: int) -> None:
    """Both truncation models of one analysis (target ``goal`` and ``goal | extra``):
    each model's decided sets and values are its own brute force's."""
    mdp = small_mdp(seed + 100, n=7)
    extra = np.zeros(mdp.n_states, dtype=bool)
    extra[mdp.n_states - 2] = True  # the sink counts as reached in the upper model
    low, high = analyse(mdp, mdp.target, extra, sense=Sense.MIN)
    for q, target in ((low, mdp.target), (high, mdp.target | extra)):
        pmin, _ = brute_force(mdp, target)
        assert [bool(z) for z in q.qualitative.zero] == [v == 0 for v in pmin]
        assert [bool(o) for o in q.qualitative.one] == [v == 1 for v in pmin]
        lp = solve_lp(mdp, target, quotient=q, sense=Sense.MIN, everywhere=True)
        assert lp.status is Status.OPTIMAL
        exact = evaluate_policy(mdp, target, lp.policy)
        for s in range(mdp.n_states):
            assert exact[s] == pytest.approx(float(pmin[s]), rel=1e-12, abs=1e-300), s


# --------------------------------------------------------------------------- the solvers


@pytest.mark.parametrize("rare", [1.0, 1e-20])
@pytest.mark.parametrize("seed", range(8))
def test_minimum_against_every_policy(seed: int, rare: float) -> None:
    """Interval iteration brackets Pmin of every state within the relative precision,
    and the LP's policy is worth the minimum (exactly: relative 1e-12), also when the
    values are powers of 1e-20."""
    mdp = small_mdp(seed, rare=rare)
    pmin, pmax = brute_force(mdp, mdp.target)
    it = interval_iteration(mdp, mdp.target, sense=Sense.MIN, gap="max", progress=False)
    assert it.status is Status.OPTIMAL
    for s in range(mdp.n_states):
        exact = pmin[s]
        assert Fraction(float(it.lower[s])) <= exact * (1 + Fraction(1, 10**12)), s
        assert Fraction(float(it.upper[s])) >= exact * (1 - Fraction(1, 10**12)), s
        assert Fraction(float(it.upper[s] - it.lower[s])) <= Fraction(1, 10**6) * exact, s
    lp = solve_lp(mdp, mdp.target, sense=Sense.MIN, everywhere=True,
                  bounds=(it.lower, it.upper))
    assert lp.status is Status.OPTIMAL
    worth = evaluate_policy(mdp, mdp.target, lp.policy)
    for s in range(mdp.n_states):
        assert _within(float(worth[s]), pmin[s], 1e-12), (s, worth[s], float(pmin[s]))
    # the greedy policy of the iteration is worth the minimum too (within its bracket)
    greedy = evaluate_policy(mdp, mdp.target, it.policy)
    assert np.all(greedy <= it.upper * (1 + 1e-12))
    # and the maximum of the same model keeps its own answer
    top = solve_lp(mdp, mdp.target, everywhere=True)
    best = evaluate_policy(mdp, mdp.target, top.policy)
    for s in range(mdp.n_states):
        assert _within(float(best[s]), pmax[s], 1e-12), s


@pytest.mark.parametrize("layout", list(Layout))
def test_minimum_lp_routes_agree_on_random_models(layout: Layout) -> None:
    """The block LPs and the one monolithic LP give the brute-force minimum."""
    for seed in range(4):
        mdp = small_mdp(seed + 40)
        pmin, _ = brute_force(mdp, mdp.target)
        lp = solve_lp(mdp, mdp.target, sense=Sense.MIN, layout=layout,
                      everywhere=True)
        assert lp.status is Status.OPTIMAL
        worth = evaluate_policy(mdp, mdp.target, lp.policy)
        for s in range(mdp.n_states):
            assert _within(float(worth[s]), pmin[s], 1e-12), (seed, s)


def _cycle(stay: float, rare: tuple[float, float]) -> MDP:
    """Two states that pass the run to each other with ``stay``; each may enter the
    target with ``rare[0]`` (choice ``a``) or ``rare[1]`` (``b``), else the sink.
    By hand, each optimum is ``rare / (1 - stay)`` in both states."""
    from conftest import build_mdp

    def gamble(other: int, p: float) -> dict[int, float]:
        return {other: stay, 2: p, 3: 1.0 - stay - p}

    return build_mdp([[("a", gamble(1, rare[0])), ("b", gamble(1, rare[1]))],
                      [("a", gamble(0, rare[0])), ("b", gamble(0, rare[1]))], [], []],
                     target=[2], sink=[3])


@pytest.mark.parametrize("sense", [Sense.MIN, Sense.MAX])
def test_the_iteration_stops_on_a_relative_gap(sense: Sense) -> None:
    """A cycle of values 2e-12 / 6e-12: closed to ``tol`` = 1e-9 alone the bracket says
    nothing of them; with the relative precision (the default, 1e-6) it holds the
    closed form to six digits."""
    mdp = _cycle(0.5, (1e-12, 3e-12))
    exact = Fraction(1e-12 if sense is Sense.MIN else 3e-12) / (1 - Fraction(0.5))
    loose = interval_iteration(mdp, mdp.target, sense=sense, precision=None, gap="max",
                               progress=False)
    tight = interval_iteration(mdp, mdp.target, sense=sense, gap="max", progress=False)
    for r in (loose, tight):
        assert r.status is Status.OPTIMAL
        assert Fraction(r.value_lower) <= exact <= Fraction(r.value_upper)
    assert loose.value_upper - loose.value_lower < 1e-9
    assert loose.value_upper - loose.value_lower > 1e-6 * float(exact)
    assert tight.value_upper - tight.value_lower <= 1e-6 * float(exact)


@pytest.mark.parametrize("sense", [Sense.MIN, Sense.MAX])
def test_a_slow_rare_block_is_jumped_to_relative_precision(sense: Sense) -> None:
    """A cycle left once in a thousand steps, values 1e-17 / 2e-17: a sweep shrinks the
    gap by 0.999, so six digits would take some 14,000 sweeps; the policy jump (checked
    on the policy's choices for its own bound, on every choice for the other, in the
    sense asked) proves both after a hundred."""
    mdp = _cycle(0.999, (1e-20, 2e-20))
    rate = Fraction(1e-20 if sense is Sense.MIN else 2e-20)
    exact = rate / (1 - Fraction(0.999))
    r = interval_iteration(mdp, mdp.target, sense=sense, gap="max", progress=False)
    assert r.status is Status.OPTIMAL, r.message
    assert r.iterations < 1000
    for s in (0, 1):
        assert Fraction(float(r.lower[s])) <= exact <= Fraction(float(r.upper[s]))
        assert r.upper[s] - r.lower[s] <= 1e-6 * float(exact)
    # the policy: the rarer gamble for the least, the likelier for the most
    assert mdp.action_name(int(r.policy[0])) == ("a" if sense is Sense.MIN else "b")


@pytest.mark.parametrize("sense", [Sense.MIN, Sense.MAX])
def test_policy_iteration_tells_rare_choices_apart(sense: Sense) -> None:
    """Policy iteration on the cycle's block, started from the wrong gamble in both
    states, switches to the right one: the gain (about 1e-20 a step) is judged relative
    to the values compared (1e-17), not to 1; the values are the closed form's."""
    from mitld_lp.solvers.quotient import reduce
    from mitld_lp.solvers.topological import Block, improve_policy

    mdp = _cycle(0.999, (1e-20, 2e-20))
    q = reduce(mdp, mdp.target, sense=sense)
    block = Block.of(q, np.arange(q.n_states))
    wrong = 1 if sense is Sense.MIN else 0  # b for the least, a for the most
    start = np.asarray(block.groups[:-1]) + wrong
    chosen, v, _ = improve_policy(block, block.to_target, start, sense=sense)
    assert np.array_equal(chosen, np.asarray(block.groups[:-1]) + (1 - wrong))
    exact = Fraction(1e-20 if sense is Sense.MIN else 2e-20) / (1 - Fraction(0.999))
    for value in v:
        assert _within(float(value), exact, 1e-12), float(value)


def test_a_quotient_answers_only_the_sense_it_was_reduced_for() -> None:
    mdp = small_mdp(3)
    q = analyse(mdp, mdp.target, sense=Sense.MIN)[0]
    with pytest.raises(ValueError, match="reduced for a minimum, not the maximum"):
        solve_lp(mdp, mdp.target, quotient=q)


# --------------------------------------------------------------------------- rare events

# Six stages, each failing by a slow fault (1e-7 a try, retried half the time) or a
# fast one (3e-6), or (from stage 2 on) sent back a stage (1e-6 of failing on the way):
# stages 1-5 form one cycle, so
# the minimum and the maximum are solved on a block of five states; at stage 0 the
# system may also be shut down for ever (the minimum is 0 from there: Prob0E).
CASCADE = """mdp
module cascade
  s : [0..7] init 0;
  off : bool init false;
  [slow] s<6 & !off -> 0.0000001 : (s'=s+1) + 0.5 : (s'=s) + 0.4999999 : (s'=7);
  [fast] s<6 & !off -> 0.000003 : (s'=s+1) + 0.999997 : (s'=7);
  [back] s>1 & s<6 & !off -> 0.3 : (s'=s-1) + 0.000001 : (s'=s+1) + 0.699999 : (s'=7);
  [stop] s=0 & !off -> (off'=true);
  [idle] off -> true;
  [done] s>=6 -> true;
endmodule
label "hit" = s=6;
"""


def _model(tmp_path: Path, text: str, spec: str, objective: str) -> Path:
    prism = tmp_path / "m.prism"
    prism.write_text(text)
    path = tmp_path / f"m_{objective}.toml"
    path.write_text(f'name = "rare"\nspec = "{spec}"\nobjective = "{objective}"\n\n'
                    f'[prism]\nfile = "{prism.name}"\n')
    return path


@needs_storm
@pytest.mark.parametrize(("objective", "float_exact"), [
    ("min", Fraction(0.001) ** 10), ("max", Fraction(0.0011) ** 10)])
def test_the_issues_rare_example(tmp_path: Path, objective: str,
                                 float_exact: Fraction) -> None:
    """The issue's 12-state MDP: ``F hit`` is 1e-30 at least and 0.0011**10 at most
    (Storm, exact); the bracket holds the decimal model's optimum exactly and is
    within relative 1e-11 of it (the certificate's allowance for the stored floats,
    2^-44 a probability over ten steps), not [0, 0] (the minimum read back from 1 - the
    complement's maximum) nor a policy a thousand times worse."""
    path = _model(tmp_path, RARE, "F hit", objective)
    storm = storm_rational(tmp_path / "m.prism", f'P{objective}=? [F "hit"]')
    assert storm == (Fraction(1, 10**30) if objective == "min"
                     else Fraction(25937424601, 10**40))
    for method in ("lp", "vi"):
        r = synthesize(load_model(path), method=method)
        assert r.certified, r.failed_checks
        assert r.sense == objective and not r.complemented
        assert Fraction(r.lower) <= storm <= Fraction(r.upper)
        for end in (r.lower, r.upper):
            assert _within(end, float_exact, 1e-11), (method, end, float(float_exact))
            assert _within(end, storm, 1e-11)
        # the controller plays the same choice every step: a for the least, b for the most
        first = int(r.lower_model.policy[r.mdp.initial])
        assert r.mdp.action_name(first) == ("a" if objective == "min" else "b")


@needs_storm
@pytest.mark.parametrize("objective", ["min", "max"])
@pytest.mark.parametrize("start", [0, 4])
def test_a_fault_cascade_to_six_digits(tmp_path: Path, objective: str, start: int) -> None:
    """A cascade of six rare faults with a cycle through the stages (a block of five
    states): the bracket contains Storm's exact value and is at most 1e-6 of it wide.
    From stage 0 the minimum is 0 (shut down): the graph says so, exactly."""
    text = CASCADE.replace("s : [0..7] init 0", f"s : [0..7] init {start}")
    path = _model(tmp_path, text, "F hit", objective)
    r = synthesize(load_model(path))
    assert r.certified, r.failed_checks
    exact = storm_rational(tmp_path / "m.prism", f'P{objective}=? [F "hit"]')
    if exact == 0:
        assert objective == "min" and start == 0
        assert r.lower == r.upper == 0.0
        return
    assert exact < Fraction(1, 10**8)  # rare: below any absolute tolerance
    # the float model differs from the decimal one by a few roundings a step
    assert Fraction(r.lower) <= exact * (1 + Fraction(1, 10**12))
    assert Fraction(r.upper) >= exact * (1 - Fraction(1, 10**12))
    assert Fraction(r.upper - r.lower) <= Fraction(1, 10**6) * exact


def test_a_co_safe_minimum_runs_its_own_automaton_a_safety_one_the_complement() -> None:
    """By hand on a fork: ``a`` reaches A w.p. 0.6, ``b`` w.p. 0.2.  Minimising ``F A``
    is solved on its own automaton (the controller's runs accept when A is reached);
    ``G !A``, a task with a safety part, on its complement.  The simulation of each
    controller estimates the task's own probability, whichever automaton it runs."""
    from mitld_lp import Model, simulate
    from mitld_lp.worlds.game import ExplicitGame

    fork = ExplicitGame(
        initial="s",
        transitions={"s": {"a": {"A": 0.6, "B": 0.4}, "b": {"A": 0.2, "C": 0.8}},
                     "A": {"wait": {"A": 1.0}}, "B": {"wait": {"B": 1.0}},
                     "C": {"wait": {"C": 1.0}}},
        labels={"A": {"A"}, "B": {"B"}, "C": {"C"}})
    for spec, direct, task in (("F A", True, 0.2), ("G !A", False, 0.4)):
        r = synthesize(Model.from_game(fork, spec, objective="min"))
        assert r.certified and r.complemented is not direct
        assert r.sense == ("min" if direct else "max")
        assert r.lower == pytest.approx(task, abs=1e-12)
        assert r.upper == pytest.approx(task, abs=1e-12)
        sim = simulate(Model.from_game(fork, spec, objective="min"), r.controller,
                       runs=2000, seed=1, max_steps=5)
        assert sim.ci_low <= task <= sim.ci_high, (spec, sim)


@needs_storm
def test_a_bundled_minimum_is_storms_on_its_own_product(tmp_path: Path) -> None:
    """models/red_light.toml minimised (a co-safe task with truncated events): the
    upper end is the controller's exact value with truncation counted as the task
    happening, the lower end the least with truncation counted against it; Storm's
    sound value iteration (relative 1e-13) on the product written as DRN, for each
    target, gives the same minima to 1e-11 (read back from the complement's maximum the upper end
    was 7.794158388474415e-06, off by 4e-11 of itself)."""
    import stormpy
    import stormpy.environments as envs

    from mitld_lp.solvers import write_drn

    root = Path(__file__).resolve().parent.parent
    r = synthesize(load_model(root / "models" / "red_light.toml"), objective="min")
    assert r.certified and r.sense == "min" and r.sta.truncation_points
    env = stormpy.Environment()
    env.solver().force_soundness = True
    minmax = env.solver().min_max()
    minmax.method = envs.MinMaxMethod.SOUND_VALUE_ITERATION
    minmax.precision = stormpy.Rational("1/10000000000000")
    minmax.relative_termination_criterion = True
    prop = stormpy.parse_properties('Pmin=? [F "target"]')[0]
    goal = np.asarray(r.acceptance.goal)
    for target, ours in ((goal | np.asarray(r.mdp.truncated), r.upper), (goal, r.lower)):
        path = write_drn(r.mdp, target, tmp_path / "p.drn", overwrite=True)
        model = stormpy.build_model_from_drn(str(path))
        value = stormpy.model_checking(model, prop, environment=env).get_value(
            model.initial_states[0])
        # the certified ends hold for the decimals as written: their allowance for the
        # stored floats (2^-44 a probability over the steps) is about 1e-12 of the value
        assert ours == pytest.approx(value, rel=1e-11, abs=1e-300)
    assert r.upper > 7e-6

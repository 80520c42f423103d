"""Brackets that hold in exact arithmetic (mitld_lp.solvers.certify, issue 40).

Every expected value is exact and independent of the code under test: a closed form
in ``fractions.Fraction``, policies enumerated and solved here in rational arithmetic,
or Storm's exact engine (``stormpy.build_model[stormpy.Rational]``).  Every comparison
is ``Fraction(lower) <= exact <= Fraction(upper)``, with no tolerance."""

from __future__ import annotations

import itertools
import json
import random
from fractions import Fraction
from math import comb
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from storm_exact import RARE, storm_rational

from mitld_lp import ExplicitGame, Model, load_model, synthesize
from mitld_lp.cli import main
from mitld_lp.distributions.literal import from_table
from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.report import bracket_text, probability_text
from mitld_lp.solvers import certify as C

stormpy = pytest.importorskip("stormpy")

WALK = """mdp
module walk
  k : [0..13] init 0;
  [go] k<12 -> 0.7 : (k'=k+1) + 0.2 : (k'=k) + 0.1 : (k'=13);
  [rest] k>=12 -> true;
endmodule
label "home" = k>=HOME & k<13;
label "lost" = k=13;
"""


def model_file(tmp_path: Path, name: str, prism: str, spec: str, objective: str = "max",
               ) -> Path:
    (tmp_path / f"{name}.prism").write_text(prism)
    path = tmp_path / f"{name}.toml"
    path.write_text(f'name = "{name}"\nspec = "{spec}"\nobjective = "{objective}"\n'
                    f'[prism]\nfile = "{name}.prism"\n')
    return path


def storm_exact(prism: str, prop: str, tmp_path: Path) -> Fraction:
    """Storm's exact engine on the program: the property's value at the initial state."""
    path = tmp_path / "exact.prism"
    path.write_text(prism)
    return storm_rational(path, prop)


def inside(lower: float, exact: Fraction, upper: float) -> bool:
    return Fraction(lower) <= exact <= Fraction(upper)


# ------------------------------------------------------------------ the walk


@pytest.mark.parametrize("home", [3, 8, 12])
def test_a_walk_with_decimal_branches_is_bracketed_exactly(tmp_path, home) -> None:
    # The main branch gave a point bracket one rounding off the exact value for each of
    # these.  Closed form: reach `home` within 15 steps, never lost: `home` moves
    # forward (0.7), j stays (0.2) placed among the first home - 1 + j steps.
    exact = sum(comb(home - 1 + j, j) * Fraction(7, 10) ** home * Fraction(2, 10) ** j
                for j in range(16 - home))
    prism = WALK.replace("HOME", str(home))
    assert storm_exact(prism, 'Pmax=? [!"lost" U<=15 "home"]', tmp_path) == exact
    r = synthesize(load_model(model_file(tmp_path, "walk", prism, "!lost U[0,15] home")))
    assert r.certified and inside(r.lower, exact, r.upper)
    assert Fraction(r.upper) - Fraction(r.lower) <= Fraction(1, 10**6) * exact
    # the JSON record carries the same full-precision floats
    assert r.summary()["lower"] == r.lower and r.summary()["upper"] == r.upper


# ------------------------------------------------------------------ rare events


def rare_product(tmp_path: Path, spec: str = "F hit", objective: str = "max"):
    r = synthesize(load_model(model_file(tmp_path, "rare", RARE, spec, objective)))
    return r


def always(mdp: MDP, action: str) -> np.ndarray:
    """The policy playing ``action`` wherever it is offered (-1 where absorbing)."""
    policy = np.full(mdp.n_states, -1, dtype=np.int64)
    for s in range(mdp.n_states):
        for c in mdp.choices(s):
            if mdp.action_name(c) == action or (policy[s] < 0 and
                                                mdp.choice_actions[c] != ABSORB):
                policy[s] = c
    return policy


def test_rare_values_are_bracketed_to_relative_precision(tmp_path) -> None:
    r = rare_product(tmp_path)
    mdp, goal, zero = r.mdp, r.acceptance.goal, r.lower_model.prob0
    pmax = storm_exact(RARE, 'Pmax=? [F "hit"]', tmp_path)
    pmin = storm_exact(RARE, 'Pmin=? [F "hit"]', tmp_path)
    assert pmax == Fraction(11, 10000) ** 10 and pmin == Fraction(1, 1000) ** 10
    best = C.certify(mdp, goal, always(mdp, "b"), sense="max", zero=zero)
    assert best.certified and inside(best.lower, pmax, best.upper)
    assert Fraction(best.upper) - Fraction(best.lower) <= Fraction(1, 10**6) * pmax
    # a minimum: the states from which some policy avoids `hit` for ever are, here, the
    # ones from which no policy reaches it (every choice reaches it with positive odds)
    least = C.certify(mdp, goal, always(mdp, "a"), sense="min", zero=zero)
    assert least.certified and inside(least.lower, pmin, least.upper)
    assert Fraction(least.upper) - Fraction(least.lower) <= Fraction(1, 10**6) * pmin
    assert least.lower > 0  # strictly positive, never certified as 0
    # the worse policy's own value is bracketed too, and the optimum is still bounded
    worse = C.certify(mdp, goal, always(mdp, "a"), sense="max", zero=zero)
    assert Fraction(worse.lower) <= pmin and Fraction(worse.upper) >= pmax


def test_a_safety_minimum_near_one_keeps_the_complement_digits(tmp_path, capsys) -> None:
    # G !hit with min = 1 - Pmax(F hit): the task's bracket is [1 - b, 1 - a] rounded
    # outward (never [1, 1]), the complement's [a, b] holds Pmax(F hit) exactly
    r = rare_product(tmp_path, "G !hit", "min")
    pmax = storm_exact(RARE, 'Pmax=? [F "hit"]', tmp_path)
    assert storm_exact(RARE, 'Pmin=? [G !"hit"]', tmp_path) == 1 - pmax
    assert r.certified and r.complement is not None
    assert inside(r.complement[0], pmax, r.complement[1])
    assert inside(r.lower, 1 - pmax, r.upper) and r.lower < 1.0
    summary = r.summary()
    assert summary["complement"] == list(r.complement)
    assert main(["solve", str(tmp_path / "rare.toml"), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["complement"] == list(r.complement) and printed["lower"] == r.lower
    assert main(["solve", str(tmp_path / "rare.toml")]) == 0
    text = capsys.readouterr().out
    assert "complement:   1 - optimum in [" in text


# ------------------------------------------------------------------ random MDPs


def random_mdp(rng: random.Random, n: int, actions: int):
    """A random MDP with three-digit decimal probabilities: the floats (an MDP record)
    and the exact rows (Fractions); state n-2 the target, n-1 a sink, state 0 with a
    self-loop choice (an end component with the target out of reach on it)."""
    rows, exact, groups, acts = [], [], [0], []
    for s in range(n):
        if s >= n - 2:
            rows.append({s: 1.0})
            exact.append({s: Fraction(1)})
            acts.append(ABSORB)
            groups.append(len(rows))
            continue
        for a in range(actions):
            if s == 0 and a == 0:
                succ = {0: Fraction(1)}
            else:
                k = rng.randint(1, 3)
                targets = rng.sample(range(n), k)
                cuts = sorted(rng.sample(range(1, 1000), k - 1))
                parts = [b - a_ for a_, b in zip([0, *cuts], [*cuts, 1000], strict=True)]
                succ = {t: Fraction(p, 1000) for t, p in zip(targets, parts, strict=True)}
            exact.append(succ)
            rows.append({t: float(p) for t, p in succ.items()})
            acts.append(a)
        groups.append(len(rows))
    data, cols, ptr = [], [], [0]
    for row in rows:
        for t in sorted(row):
            cols.append(t)
            data.append(row[t])
        ptr.append(len(cols))
    matrix = sp.csr_array((np.array(data), np.array(cols), np.array(ptr)),
                          shape=(len(rows), n))
    target = np.zeros(n, dtype=bool)
    target[n - 2] = True
    sink = np.zeros(n, dtype=bool)
    sink[n - 1] = True
    mdp = MDP(matrix=matrix, row_groups=np.array(groups, dtype=np.int64),
              choice_actions=np.array(acts, dtype=np.int32),
              action_names=tuple(f"a{i}" for i in range(actions)), initial=0,
              target=target, sink=sink, truncated=np.zeros(n, dtype=bool),
              states=list(range(n)))
    return mdp, exact


def exact_value(mdp: MDP, exact: list, target: np.ndarray, policy: tuple) -> list:
    """The policy's value in rational arithmetic: Gaussian elimination on the states
    that can reach the target in its chain."""
    n = mdp.n_states
    row = {s: exact[policy[s]] for s in range(n)}
    can = set(np.flatnonzero(target).tolist())
    grew = True
    while grew:
        grew = False
        for s in range(n):
            if s not in can and any(t in can and p > 0 for t, p in row[s].items()):
                can.add(s)
                grew = True
    unknown = [s for s in range(n) if s in can and not target[s]]
    at = {s: i for i, s in enumerate(unknown)}
    k = len(unknown)
    a = [[Fraction(int(i == j)) for j in range(k)] + [Fraction(0)] for i in range(k)]
    for s in unknown:
        for t, p in row[s].items():
            if target[t]:
                a[at[s]][k] += p
            elif t in at:
                a[at[s]][at[t]] -= p
    for i in range(k):  # no pivoting needed: I - Q of a transient chain
        piv = next(r for r in range(i, k) if a[r][i] != 0)
        a[i], a[piv] = a[piv], a[i]
        for r in range(k):
            if r != i and a[r][i] != 0:
                f = a[r][i] / a[i][i]
                a[r] = [x - f * y for x, y in zip(a[r], a[i], strict=True)]
    value = [Fraction(1) if target[s] else Fraction(0) for s in range(n)]
    for s in unknown:
        value[s] = a[at[s]][k] / a[at[s]][at[s]]
    return value


@pytest.mark.parametrize("seed", range(6))
def test_random_mdps_against_every_policy_in_rational_arithmetic(seed) -> None:
    rng = random.Random(seed)
    mdp, exact = random_mdp(rng, 7, 2)
    target = np.asarray(mdp.target)
    choices = [list(mdp.choices(s)) for s in range(mdp.n_states)]
    values = {pol: exact_value(mdp, exact, target, pol)
              for pol in itertools.product(*choices)}
    pmax = [max(v[s] for v in values.values()) for s in range(mdp.n_states)]
    pmin = [min(v[s] for v in values.values()) for s in range(mdp.n_states)]
    zero_max = np.array([p == 0 for p in pmax])
    zero_min = np.array([p == 0 for p in pmin])
    s0 = mdp.initial
    best = max(values, key=lambda pol: [values[pol][s] for s in range(mdp.n_states)])
    for pol in (best, *rng.sample(sorted(values), 3)):
        policy = np.array([-1 if target[s] or mdp.sink[s] else c for s, c in enumerate(pol)])
        high = C.certify(mdp, target, policy, sense="max", zero=zero_max, precision=1e-6)
        assert Fraction(high.lower) <= values[pol][s0] and Fraction(high.upper) >= pmax[s0]
        low = C.certify(mdp, target, policy, sense="min", zero=zero_min)
        assert Fraction(low.lower) <= pmin[s0] and Fraction(low.upper) >= values[pol][s0]
    policy = np.array([-1 if target[s] or mdp.sink[s] else c for s, c in enumerate(best)])
    high = C.certify(mdp, target, policy, sense="max", zero=zero_max, precision=1e-6)
    assert high.certified and inside(high.lower, pmax[s0], high.upper)
    assert Fraction(high.upper) - Fraction(high.lower) <= Fraction(1, 10**9) * max(
        pmax[s0], Fraction(1, 10**300))


def test_a_minimum_without_the_states_that_avoid_the_target_is_refused() -> None:
    # state 0's self-loop avoids the target for ever: Pmin(0) = 0.  Told that no state
    # does, the certificate finds the end component and falls back to the bound 0.
    mdp, _ = random_mdp(random.Random(3), 7, 2)
    target = np.asarray(mdp.target)
    first = np.array(mdp.row_groups[:-1], dtype=np.int64)  # state 0: its self-loop
    first[-2:] = -1
    cert = C.certify(mdp, target, first, sense="min", zero=np.asarray(mdp.sink))
    assert cert.lower == 0.0 and not cert.certified
    assert any("end components outside the zero set" in c.detail for c in cert.checks)


# ------------------------------------------------------------------ the allowance eta


def prism_rows(text: str, tmp_path: Path, exact: bool) -> dict:
    """Each (state valuation, action) -> {successor valuation: probability} as Storm
    builds the program, in floats or in rational arithmetic."""
    path = tmp_path / "world.prism"
    path.write_text(text)
    program = stormpy.parse_prism_program(str(path))
    options = stormpy.BuilderOptions()
    options.set_build_state_valuations()
    options.set_build_choice_labels()
    model = (stormpy.build_model[stormpy.Rational] if exact else stormpy.build_model)(
        program, options=options)
    names = [json.dumps(json.loads(str(model.state_valuations.to_json(s))),
                        sort_keys=True) for s in range(model.nr_states)]
    out = {}
    for state in model.states:
        for action in state.actions:
            labels = model.choice_labeling.get_labels_of_choice(
                model.transition_matrix.get_row_group_start(state.id) + action.id)
            out[names[state.id], tuple(sorted(labels))] = {
                names[t.column]: Fraction(str(t.value)) if exact else t.value
                for t in action.transitions}
    return out


PROGRAMS = {
    "rare": RARE,
    "walk": WALK.replace("HOME", "5"),
    "decimals": """mdp
const double p = 0.999999999;
const double q = 0.123456789;
module m
  k : [0..3] init 0;
  [a] k=0 -> p : (k'=1) + (1-p) : (k'=2);
  [b] k=0 -> 1/3 : (k'=1) + 2/3 : (k'=2);
  [c] k=0 -> q*q : (k'=1) + q*(1-q) : (k'=2) + (1-q) : (k'=3);
  [d] k>0 -> 0.1 : (k'=0) + 0.7 : (k'=1) + 0.2 : (k'=3);
endmodule
""",
}


@pytest.mark.parametrize("name", sorted(PROGRAMS))
def test_storm_stores_each_probability_within_eta_of_the_exact_one(tmp_path, name) -> None:
    # The claim ETA rests on (mitld_lp.solvers.certify): the world's floats, as Storm
    # builds them for the product, within ETA (relative) of the program's decimals.
    floats = prism_rows(PROGRAMS[name], tmp_path, exact=False)
    exact = prism_rows(PROGRAMS[name], tmp_path, exact=True)
    assert floats.keys() == exact.keys()
    for key, row in exact.items():
        assert row.keys() == floats[key].keys()  # the same support
        for succ, p in row.items():
            assert abs(Fraction(floats[key][succ]) - p) <= Fraction(C.ETA) * p


def test_the_allowance_grows_with_a_cancelling_hazard() -> None:
    from mitld_lp.automata.sta import make_sta
    from mitld_lp.automata.translate import to_dta
    from mitld_lp.distributions import geometric
    from mitld_lp.logic.fragment import check
    from mitld_lp.logic.parser import parse

    report = check(parse("D[mu] b & F b"))
    dta = to_dta(report)
    mild = make_sta(dta, {"b": geometric(0.5)}, 0.01)
    near_one = make_sta(dta, {"b": geometric(1 - 1e-9)}, 0.01)
    assert C.model_eta(mild) == pytest.approx(C.ETA + C.HAZARD_ACCURACY, rel=1e-12)
    # 1 - h computed from h accurate to HAZARD_ACCURACY: error h/(1-h) times that
    assert C.model_eta(near_one) >= C.ETA + (1 - 1e-9) / 1e-9 * C.HAZARD_ACCURACY * 0.99


def test_an_allowance_past_its_limit_fails_the_checks_soundly(tmp_path) -> None:
    r = rare_product(tmp_path)
    mdp, goal, zero = r.mdp, r.acceptance.goal, r.lower_model.prob0
    pmax = Fraction(11, 10000) ** 10
    wide = C.certify(mdp, goal, always(mdp, "b"), sense="max", zero=zero, eta=2.0**-4)
    assert inside(wide.lower, pmax, wide.upper)  # loose, still sound
    # past the limit a row's sum is bounded by 0 and infinity: the trivial bracket,
    # proved, and the policy not shown optimal to any precision
    past = C.certify(mdp, goal, always(mdp, "b"), sense="max", zero=zero, eta=0.2,
                     precision=1e-6)
    assert (past.lower, past.upper) == (0.0, 1.0) and not past.certified


# ------------------------------------------------------------------ robust and printing


def test_a_robust_bracket_holds_the_exact_worst_case() -> None:
    # waiting for an event with a hazard in [0.2, 0.4] within 4 steps: the worst law
    # takes 0.2 at every step, 1 - 0.8^4 = 369/625
    still = ExplicitGame(initial="here", transitions={"here": {"wait": {"here": 1.0}}})
    law = from_table({"geometric": [0.2, 0.4]}, "mu")
    r = synthesize(Model.from_game(still, "D[mu] b & F[0,4] b", distributions={"mu": law}))
    assert r.certified and inside(r.lower, Fraction(369, 625), r.upper)
    assert Fraction(r.upper) - Fraction(r.lower) <= Fraction(1, 10**9)


@pytest.mark.parametrize("seed", range(3))
def test_printed_brackets_round_outward(seed) -> None:
    rng = np.random.default_rng(seed)
    for x in np.concatenate([rng.random(200), 10.0 ** rng.uniform(-40, 0, 200),
                             [0.0, 1.0, 0.7, 1 - 2**-53, 2.5937424601e-30]]):
        x = float(x)
        down, up = probability_text(x, "down"), probability_text(x, "up")
        assert Fraction(down) <= Fraction(x) <= Fraction(up)
        # one unit of the 7th decimal, or of the 7th significant digit below 1e-3
        unit = Fraction(1, 10**7) if x == 0 or x >= 1e-3 else Fraction(x) / 10**6
        assert Fraction(up) - Fraction(down) <= unit
    assert bracket_text(0.6999999999999999, 0.7000000000000001) == "[0.6999999, 0.7000001]"
    assert bracket_text(0.25, 0.25) == "[0.2500000, 0.2500000]"


def test_precision_is_an_option_everywhere(tmp_path, capsys) -> None:
    path = model_file(tmp_path, "walk", WALK.replace("HOME", "5"), "!lost U[0,15] home")
    assert main(["solve", str(path), "--json", "--precision", "1e-3"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["precision"] == 1e-3 and record["width"]["truncation"] == 0.0
    assert main(["solve", str(path), "--precision", "2"]) == 2
    assert "--precision" in capsys.readouterr().err
    r = synthesize(load_model(path), precision=1e-3)
    assert r.precision == 1e-3 and r.certified
    with pytest.raises(ValueError, match="precision"):
        synthesize(load_model(path), precision=0.0)


# ------------------------------------------------------------------ constraints

SLOW = """mdp
module m
  x : [0..1] init 0;
  [go] x=0 -> 0.7 : (x'=1) + 0.3 : (x'=0);
  [done] x=1 -> true;
endmodule
label "goal" = x=1;
"""


def test_a_constraint_holds_only_when_its_certified_bound_meets_it(tmp_path) -> None:
    from mitld_lp.synthesis import synthesize_constrained

    model = load_model(model_file(tmp_path, "slow", SLOW, "F goal"))
    # the least expected steps is exactly 10/7; the float just below cannot be met
    below_min = float(Fraction(10, 7))
    while Fraction(below_min) >= Fraction(10, 7):
        below_min = float(np.nextafter(below_min, 0.0))
    r = synthesize_constrained(model, [f"E(steps) <= {below_min!r}"])
    assert not r.certified
    if r.status == "optimal":
        (c,) = r.constraints
        assert not c.holds and c.miss > 0 and Fraction(c.certified) >= Fraction(10, 7)
    ok = synthesize_constrained(model, ["E(steps) <= 1.43"])
    (c,) = ok.constraints
    assert ok.certified and c.holds
    assert Fraction(c.bounds[0]) <= Fraction(10, 7) <= Fraction(c.bounds[1]) <= Fraction("1.43")


def test_a_binding_constraint_holds_for_the_policys_exact_value(tmp_path) -> None:
    # main printed "P(F puddle) <= 0.05: 0.05000006 (holds)"; now the policy meets the
    # bound, which Storm's exact engine confirms on the controlled chain (its DRN holds
    # the stored floats, an exact model within eta of the decimals)
    from mitld_lp.running.chain import write_chain
    from mitld_lp.synthesis import synthesize_constrained

    models = Path(__file__).resolve().parents[1] / "models"
    r = synthesize_constrained(load_model(models / "bus_risk.toml"),
                               ["P(F puddle) <= 0.05"], then="min-steps")
    (c,) = r.constraints
    assert r.certified and c.holds and c.bounds[1] <= 0.05
    chain = stormpy.build_model_from_drn[stormpy.Rational](
        str(write_chain(r, tmp_path / "chain.drn")))

    def exact(prop: str) -> Fraction:
        result = stormpy.model_checking(chain, stormpy.parse_properties(prop)[0])
        return Fraction(str(result.get_value(chain.initial_states[0])))

    assert inside(c.bounds[0], exact('P=? [F "puddle"]'), c.bounds[1])
    assert Fraction(r.lower) <= exact('P=? [F "accept"]') <= Fraction(r.upper)


def test_an_upper_bound_does_not_take_a_wrong_zero_set_on_trust() -> None:
    # told that no state reaches the target, the maximum's bound still holds: its 0s
    # are candidates, checked (and raised) like every other value
    rng = random.Random(1)
    mdp, exact = random_mdp(rng, 7, 2)
    target = np.asarray(mdp.target)
    choices = [list(mdp.choices(s)) for s in range(mdp.n_states)]
    pmax = max(exact_value(mdp, exact, target, pol)[mdp.initial]
               for pol in itertools.product(*choices))
    assert pmax > 0
    policy = np.array([-1 if target[s] or mdp.sink[s] else c[0]
                       for s, c in enumerate(choices)])
    cert = C.certify(mdp, target, policy, sense="max", zero=~target, sides=("upper",))
    assert Fraction(cert.upper) >= pmax


def test_a_constrained_bracket_holds_the_exact_optimum() -> None:
    # max P(F A) s.t. P(F B) <= 0.2 on a fork (a: A 0.6, B 0.4; b: A 0.2, C 0.8): play a
    # w.p. q, 0.4 q <= 0.2, P(F A) = 0.2 + 0.4 q is at most 2/5 (by hand); the upper
    # bound is weak duality checked in exact arithmetic, the lower the policy's value
    from mitld_lp.synthesis import synthesize_constrained

    fork = ExplicitGame(
        initial="s",
        transitions={"s": {"a": {"A": 0.6, "B": 0.4}, "b": {"A": 0.2, "C": 0.8}},
                     "A": {"wait": {"A": 1.0}}, "B": {"wait": {"B": 1.0}},
                     "C": {"wait": {"C": 1.0}}},
        labels={"A": {"A"}, "B": {"B"}, "C": {"C"}})
    r = synthesize_constrained(Model.from_game(fork, "F A"), ["P(F B) <= 0.2"])
    assert r.certified and inside(r.lower, Fraction(2, 5), r.upper)
    assert Fraction(r.upper) - Fraction(r.lower) <= Fraction(1, 10**6)
    (c,) = r.constraints
    assert c.holds and Fraction(c.bounds[1]) <= Fraction(1, 5)
    assert any(ch.name.startswith("upper bound: the constrained optimum") and ch.passed
               for ch in r.checks)

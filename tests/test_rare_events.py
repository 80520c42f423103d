"""A rare event (probability about 1e-12) in a cycle: the certified bracket holds the
closed-form value as Fractions, is within the relative precision of it, and the
iteration's sweep count stays within a bound read off the model (issue 45: a small
probability is not a trivial instance and must not cost more than its contraction).

The iteration's own float bracket is checked up to one sweep's rounding (its vectors
are rounded to nearest); the certificate's, which an answer reports, exactly."""

from __future__ import annotations

import math
from fractions import Fraction

import pytest
from conftest import build_mdp

from mitld_lp import defaults
from mitld_lp.solvers import Status, interval_iteration, solve_lp
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.certify import certify

P = 1e-3  # one coin flip succeeds
R = 0.9  # a failed flip starts over (else the run dies)
K = 4  # flips in a row to win


def _attempts(k: int = K):
    """Stages 0..k-1, then the goal k and the dead end k+1.  In each stage: ``try``
    (advance with P, start over with R, die otherwise), ``slow`` (advance with P/2:
    worse) and ``quit`` (die)."""
    goal, dead = k, k + 1
    states = []
    for i in range(k):
        nxt = i + 1
        states.append([
            ("try", {nxt: P, 0: R, dead: 1.0 - P - R}),
            ("slow", {nxt: P / 2, 0: R, dead: 1.0 - P / 2 - R}),
            ("quit", {dead: 1.0}),
        ])
    states += [[], []]
    return build_mdp(states, target=[goal], sink=[dead])


def _exact(mdp) -> Fraction:
    """The optimum from stage 0 in closed form, from the probabilities as stored: an
    attempt wins with p^K and starts over with r (1 + p + ... + p^(K-1)); the value x
    solves x = p^K + (that) x (``try`` everywhere: more of both than ``slow``)."""
    m = mdp.matrix
    row = int(mdp.row_groups[0])  # stage 0's ``try``
    p, r = Fraction(float(m[row, 1])), Fraction(float(m[row, 0]))
    again = r * sum(p ** i for i in range(K))
    return p ** K / (1 - again)


def test_rare_event_bracket_holds_the_exact_value_in_few_sweeps() -> None:
    mdp = _attempts()
    exact = _exact(mdp)
    assert 1e-12 < exact < 1e-10  # a rare event: about 1e-12 / (1 - 0.9)
    it = interval_iteration(mdp, mdp.target, progress=False)
    assert it.status is Status.OPTIMAL, it.message
    lo, hi = Fraction(it.value_lower), Fraction(it.value_upper)
    assert _near_below(lo, exact) and exact <= hi
    # relative precision, not the absolute 1e-9 (which the bracket [0, 1e-9] would meet)
    assert hi - lo <= Fraction(defaults.PRECISION) * exact
    # The bound from the model: staying in the cycle for one more step has probability
    # at most P + R under any policy, so after n sweeps every state's gap is at most
    # (P + R)^n; every state's value is at least stage 0's, so n* sweeps with
    # (P + R)^n* <= PRECISION * exact close every relative gap.  Chunks of 16 sweeps
    # between two looks at the gap, in each of the two passes, may overshoot.
    needed = math.ceil(math.log(defaults.PRECISION * float(exact)) / math.log(P + R))
    assert it.iterations <= needed + 2 * 16, (it.iterations, needed)
    # the LP stage answers the same value, and its policy tries in every stage
    lp = solve_lp(mdp, mdp.target, bounds=(it.lower, it.upper))
    assert lp.status is Status.OPTIMAL, lp.message
    assert abs(Fraction(lp.value) - exact) <= Fraction(defaults.PRECISION) * exact
    tries = [mdp.action_names[a] for a in mdp.choice_actions[lp.policy[:K]]]
    assert tries == ["try"] * K
    # the certified bracket (what an answer reports): exact arithmetic, no rounding slack
    q, _ = analyse(mdp, mdp.target)
    cert = certify(mdp, mdp.target, lp.policy, zero=q.qualitative.zero, layers=q.layers,
                   mec_of=q.mecs.mec_of, fallback_lower=it.lower, fallback_upper=it.upper,
                   precision=defaults.PRECISION)
    assert cert.certified, cert.checks
    assert Fraction(cert.lower) <= exact <= Fraction(cert.upper)
    assert Fraction(cert.upper) - Fraction(cert.lower) <= Fraction(defaults.PRECISION) * exact


def _near_below(lower: Fraction, exact: Fraction) -> bool:
    """``lower <= exact`` up to the rounding of one float64 sweep (the iteration's own
    float vectors are rounded to nearest; a state's lower bound was seen 0.1-0.2 of an
    ulp above its exact value here; the certificate's bounds, rounded outwards, are
    checked exactly above)."""
    return lower <= exact * (1 + Fraction(1, 2**51))


def test_rare_event_in_every_stage_is_bracketed() -> None:
    """Every stage's bracket (``gap="max"``) holds its own closed form: stage i wins
    with p^(K-i) and starts over into stage 0's value."""
    mdp = _attempts()
    x0 = _exact(mdp)
    m = mdp.matrix
    row = int(mdp.row_groups[0])
    p, r = Fraction(float(m[row, 1])), Fraction(float(m[row, 0]))
    it = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    assert it.status is Status.OPTIMAL, it.message
    for i in range(K):
        exact = p ** (K - i) + r * sum(p ** j for j in range(K - i)) * x0
        lo, hi = Fraction(it.lower[i]), Fraction(it.upper[i])
        assert _near_below(lo, exact) and exact <= hi, i
        assert hi - lo <= Fraction(defaults.PRECISION) * exact, i


def _bench_qvbs():
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "experiments" / "bench_qvbs.py"
    spec = importlib.util.spec_from_file_location("bench_qvbs_rule", path)
    module = importlib.util.module_from_spec(spec)
    import sys

    sys.path.insert(0, str(path.parent))
    try:
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(path.parent))
    return module


def test_bench_leaves_apart_only_what_the_graph_decides() -> None:
    """experiments/bench_qvbs.py's rule: a small probability counts in the ratios; only
    an answer the graph decides (0: the goal walled off; 1: reached surely) is apart."""
    from mitld_lp import GridWorld, Model, synthesize

    rule = _bench_qvbs().trivial

    def why(spec: str, **kw):
        world = GridWorld.make(8, 8, start=(0, 0), **kw)
        r = synthesize(Model.from_game(world, spec))
        solved = [m for m in (r.lower_model, r.upper_model) if m is not None]
        return r.lower, r.upper, rule(solved, r.mdp.initial)

    lo, hi, said = why("F[0,14] A", slip=0.5, regions={"A": [(7, 7)]})
    assert 0 < lo <= hi < 1e-3 and said is None  # rare, not trivial
    lo, hi, said = why("F A", regions={"A": [(7, 7)]}, obstacles=[(6, 7), (7, 6), (6, 6)])
    assert lo == hi == 0.0 and said is not None and said.startswith("0 by the graph")
    lo, hi, said = why("F A", slip=0.3, regions={"A": [(7, 7)]})
    assert lo == hi == 1.0 and said is not None and said.startswith("1 by the graph")


@pytest.mark.parametrize("walk_from", [2, 10**9])  # the level walk, then one LU
def test_rare_event_flow_of_the_greedy_block_is_exact(walk_from: int, monkeypatch) -> None:
    """The LP stage's block answered by the bounds' greedy policy (its threshold
    lowered to this small block) and its occupancy flow taken from that policy's own
    chain walk, transposed (``ChainLevels.solve_transposed``, not a new walk): the
    expected visits of stage i's ``try`` are p^i / (1 - r (1 + p + ... + p^(K-1))),
    in Fractions, and the primal objective is the exact rare value."""
    from mitld_lp.solvers import chain_levels, lp_blocks

    monkeypatch.setattr(lp_blocks, "GREEDY_MIN_CHOICES", 1)
    monkeypatch.setattr(chain_levels, "WALK_MIN_STATES", walk_from)
    used = []
    transposed = chain_levels.ChainLevels.solve_transposed

    def spy(self, rhs):
        used.append(self.chain.shape[0])
        return transposed(self, rhs)

    monkeypatch.setattr(chain_levels.ChainLevels, "solve_transposed", spy)
    mdp = _attempts()
    exact = _exact(mdp)
    m = mdp.matrix
    row = int(mdp.row_groups[0])
    p, r = Fraction(float(m[row, 1])), Fraction(float(m[row, 0]))
    visits = 1 / (1 - r * sum(p ** i for i in range(K)))
    it = interval_iteration(mdp, mdp.target, progress=False)
    lp = solve_lp(mdp, mdp.target, bounds=(it.lower, it.upper))
    assert lp.status is Status.OPTIMAL, lp.message
    assert "by the bounds' greedy policy" in lp.message and used == [K]
    tries = mdp.row_groups[:K]  # each stage's first choice is ``try``
    for i in range(K):
        want = p ** i * visits
        assert abs(Fraction(float(lp.occupancy[tries[i]])) - want) <= want * Fraction(1, 10**12)
    assert abs(Fraction(lp.primal_objective) - exact) <= exact * Fraction(1, 10**12)

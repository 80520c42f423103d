"""Bands with ``then`` and constraints (issue 43): the worst case over the bands of a
policy's expected steps, and constraints met under every law of the bands.

Independent routes: hand calculations on a world where nothing but the bus matters
(the expected wait at the worst law is ``1 / lo``, in fractions); Storm, on the policy's
controlled model built here as an MDP whose every choice is nature's (a corner of the
hazard box for each choice the policy takes, the policy's randomisation a fixed first
step), checked with ``Pmax``/``Pmin`` and ``Rmax=? [C]``."""

from __future__ import annotations

import importlib.util
import shutil
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from mitld_lp import ExplicitGame, Model, load_model, synthesize
from mitld_lp.automata.joint import ACCEPTED
from mitld_lp.distributions import from_table
from mitld_lp.solvers.result import Status

MODELS = Path(__file__).resolve().parent.parent / "models"


def _wait(band: list[float] | float) -> Model:
    """Nothing to do but wait for the bus: the task is decided when it comes."""
    game = ExplicitGame(initial="s0", labels={}, transitions={"s0": {"wait": {"s0": 1.0}}})
    return Model.from_game(game, "D[mu] b & F b",
                           distributions={"mu": from_table({"geometric": band}, "mu")})


def test_then_min_steps_under_a_band_is_the_wait_at_the_band_s_slowest_law() -> None:
    """Geometric hazard in [3/10, 1/2], nature choosing it step by step: the longest
    expected wait is at the lowest hazard, 1 / (3/10) = 10/3 steps (at a point law
    1/h: 2.5 at the middle law 0.4, which the middle-law LP minimises)."""
    r = synthesize(_wait([0.3, 0.5]), then="min-steps")
    assert r.route == "constrained" and r.certified and r.status == Status.OPTIMAL
    assert r.lower == pytest.approx(1.0) and r.upper == pytest.approx(1.0)
    assert Fraction(10, 3) <= Fraction(r.steps) <= Fraction(10, 3) + Fraction(1, 10**7)
    assert r.secondary == r.steps
    assert any(c.name == "worst expected steps over the bands" and c.passed
               for c in r.checks)


def test_a_steps_constraint_under_a_band_holds_at_the_worst_law_or_is_not_claimed() -> None:
    """E(steps) <= 3.4 holds at every law (worst 10/3: its certified bounds hold 10/3
    exactly); E(steps) <= 3 holds at the middle law (2.5) but not at hazard 0.3, and no
    policy does better (there is no choice): no policy is returned as meeting it."""
    ok = synthesize(_wait([0.3, 0.5]), constraints=["E(steps) <= 3.4"])
    assert ok.certified and ok.constraints[0].holds
    lo, hi = ok.constraints[0].bounds
    assert Fraction(lo) <= Fraction(10, 3) <= Fraction(hi) <= Fraction(34, 10)
    broken = synthesize(_wait([0.3, 0.5]), constraints=["E(steps) <= 3"])
    assert not broken.certified and broken.status == Status.FAILED
    assert broken.lower != broken.lower  # nan: no certified lower bound
    assert not broken.constraints[0].holds
    assert broken.constraints[0].bounds[1] > 3.0
    point = synthesize(_wait(0.3), constraints=["E(steps) <= 3"])  # the slowest law alone
    assert point.status == Status.INFEASIBLE


def _bus_fit_risk(tmp_path: Path) -> Model:
    """bus_fit (bus 1 in [0.7, 0.9], bus 2 fitted) with a puddle on the bottom row."""
    shutil.copytree(MODELS / "data", tmp_path / "data")
    path = tmp_path / "bus_fit_risk.toml"
    path.write_text((MODELS / "bus_fit.toml").read_text().replace(
        "B = [[3, 0]]", "B = [[3, 0]]\npuddle = [[1, 0], [2, 0]]"))
    return load_model(path)


def _storm_nature(result, opts, target: np.ndarray | None,  # noqa: ANN001
                  reward: np.ndarray | None, maximise: bool, tmp: Path) -> float:
    """Storm's value of the policy's controlled model with nature's corners as an MDP's
    choices: the policy takes merged choice ``c`` with its probability, a node whose
    choices are the corners of its hazard box; a stay goes to a sink.  ``target``
    (merged states, the stays' verdict by state): ``P[max|min]=? [F "t"]``; else
    ``reward`` per merged choice: ``R[max|min]=? [C]``."""
    import stormpy

    merged = result.part.merged
    prob, stay = result.part.prob, result.part.stay
    mdp = merged.mdp
    m, cs = mdp.n_states, mdp.choice_state()
    used = np.flatnonzero((prob > 0) & ~merged.absorbing[cs])
    node = {c: m + i for i, c in enumerate(used.tolist())}
    sink_t, sink_f = m + len(node), m + len(node) + 1
    n = sink_f + 1
    t = set() if target is None else set(np.flatnonzero(target & merged.absorbing).tolist())
    t.add(sink_t)
    total = np.bincount(cs, weights=prob, minlength=m) + stay
    lines, choices = [], 0

    def state(s: int, rows: list[tuple[float, dict[int, float]]]) -> None:
        nonlocal choices
        marks = " ".join(x for x, on in (("init", s == mdp.initial), ("t", s in t)) if on)
        lines.append(f"state {s} {marks}".rstrip())
        for k, (rew, out) in enumerate(rows):
            lines.append(f"\taction {k} [{float(rew)!r}]")
            lines.extend(f"\t\t{col} : {float(out[col])!r}" for col in sorted(out))
            choices += 1

    for s in range(m):
        if merged.absorbing[s]:
            state(s, [(0.0, {s: 1.0})])
            continue
        out: dict[int, float] = {}
        rew = 0.0
        for c in range(mdp.row_groups[s], mdp.row_groups[s + 1]):
            if c in node:
                out[node[c]] = prob[c] / total[s]
                rew += 0.0 if reward is None else prob[c] / total[s] * reward[c]
        if stay[s] > 0:
            sink = sink_t if target is not None and target[s] else sink_f
            out[sink] = out.get(sink, 0.0) + stay[s] / total[s]
        state(s, [(rew, out)])
    om = opts.matrix
    for c, i in node.items():
        rows = []
        for k in range(opts.groups[c], opts.groups[c + 1]):
            a, b = om.indptr[k], om.indptr[k + 1]
            rows.append((0.0, dict(zip(om.indices[a:b].tolist(), om.data[a:b].tolist(),
                                       strict=True))))
        state(i, rows)
    for sink in (sink_t, sink_f):
        state(sink, [(0.0, {sink: 1.0})])
    path = Path(tmp) / "nature.drn"
    path.write_text("@type: MDP\n@parameters\n\n@reward_models\nr\n@nr_states\n"
                    f"{n}\n@nr_choices\n{choices}\n@model\n" + "\n".join(lines) + "\n")
    model = stormpy.build_model_from_drn(str(path))
    word = "max" if maximise else "min"
    prop = f'P{word}=? [F "t"]' if target is not None else f'R{{"r"}}{word}=? [C]'
    res = stormpy.model_checking(model, stormpy.parse_properties(prop)[0])
    return float(res.get_value(model.initial_states[0]))


needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy: pip install -e '.[prism]'")


@needs_storm
@pytest.mark.parametrize("constraint", ["P(F(b2 & F[0,3] B)) <= 0.7",
                                        "P(F(b2 & F[0,3] B)) >= 0.8",
                                        "P(F(b1 & F[0,3] A)) >= 0.764"])
def test_a_band_with_a_constraint_is_met_under_every_law(constraint: str,
                                                       tmp_path: Path) -> None:
    """bus_fit with a puddle and a constraint on one bus: these were answered
    ``[nan, upper]`` (the policy optimal at the middle law broke the constraint at a
    worse law and tightening gave up).  Now a policy is found that meets it under every
    law: Storm, nature choosing a corner for every choice the policy takes, finds the
    constraint's worst case within the bound and the task's worst case at least
    ``lower``; ``upper`` is at most the constrained optimum at the middle law."""
    from mitld_lp.product.imdp import vertex_rows
    from mitld_lp.solvers.robust_merged import options
    from mitld_lp.synthesis import build_posed, pose

    posed = pose(_bus_fit_risk(tmp_path), [constraint])
    built = build_posed(posed)
    r = posed.route.solve(posed, built)
    assert r.certified and r.status == Status.OPTIMAL, r.failed_checks
    assert r.lower == r.lower and r.lower <= r.upper
    merged = r.part.merged
    opts = options(merged, vertex_rows(built.mdp))
    c = r.constraints[0].constraint
    sat = merged.verdicts[:, 1] == ACCEPTED
    sat[merged.truncated] = c.sense == "<="  # truncation counts against the constraint
    worst = _storm_nature(r, opts, sat, None, maximise=c.sense == "<=", tmp=tmp_path)
    assert (worst <= c.bound + 1e-9) if c.sense == "<=" else (worst >= c.bound - 1e-9)
    task = merged.verdicts[:, 0] == ACCEPTED
    task[merged.truncated] = False
    assert _storm_nature(r, opts, task, None, maximise=False, tmp=tmp_path) >= r.lower - 1e-9


@needs_storm
def test_then_under_a_band_brackets_storm_s_worst_expected_steps(tmp_path: Path) -> None:
    """bus_fit, ``then = min-steps``: the reported expected steps are the worst case over
    the bands of the chosen policy; Storm's ``Rmax=? [C]`` with nature choosing the
    corners on the same policy lies in the bracket (one step per undecided state)."""
    from mitld_lp.product.imdp import vertex_rows
    from mitld_lp.solvers.constrained_model import Quantity, columns
    from mitld_lp.solvers.robust_merged import options
    from mitld_lp.synthesis import build_posed, pose

    model = load_model(MODELS / "bus_fit.toml")
    posed = pose(model, then="min-steps")
    built = build_posed(posed)
    r = posed.route.solve(posed, built)
    assert r.certified, r.failed_checks
    opts = options(r.part.merged, vertex_rows(built.mdp))
    per_choice, _ = columns(r.part.merged, Quantity("steps"))
    storm = _storm_nature(r, opts, None, per_choice, maximise=True, tmp=tmp_path)
    assert storm <= r.steps + 1e-7
    assert storm >= r.steps - 1e-6
    alone = synthesize(model)  # the robust optimum: then keeps it within the precision
    assert r.lower <= alone.upper + 1e-12 and r.upper >= alone.lower - 1e-12


@needs_storm
def test_export_chain_of_a_band_with_a_constraint_is_checked_by_storm(
        tmp_path: Path) -> None:
    """``export --chain`` of bus_risk with bus 1's hazard in [0.7, 0.9] and the puddle's
    risk at most 0.1: the controlled interval model (nature's corners as its choices).
    Storm's robust check gives the task's worst case at least ``lower``, the risk's worst
    case (truncation counted as risk) at most 0.1, and the worst expected steps at most
    the answer's; each within 1e-7 of ours (the same worst case, another solver)."""
    import json

    import stormpy

    from mitld_lp.cli import main

    path = tmp_path / "risk.toml"
    path.write_text((MODELS / "bus_risk.toml").read_text()
                    .replace("mu1 = { geometric = 0.8 }", "mu1 = { geometric = [0.7, 0.9] }")
                    .replace("epsilon = 0.01",
                             'epsilon = 0.01\nconstraints = ["P(F puddle) <= 0.1"]'))
    out = tmp_path / "chain.drn"
    assert main(["export", str(path), "--chain", str(out), "-q"]) == 0
    r = synthesize(load_model(path))
    assert r.certified and r.constraints[0].holds
    model = stormpy.build_model_from_drn[stormpy.Interval](str(out))
    env = stormpy.Environment()
    env.solver().min_max().precision = stormpy.Rational("1/1000000000000")

    def check(prop: str, mode: str) -> float:
        res = stormpy.model_checking(
            model, stormpy.parse_properties(prop)[0], environment=env,
            uncertainty_resolution_mode=getattr(stormpy.UncertaintyResolutionMode, mode))
        return float(res.get_value(model.initial_states[0]))

    task = check('Pmin=? [F "accept"]', "MINIMIZE")
    risk = check('Pmax=? [F ("c1" | "truncated")]', "MAXIMIZE")
    steps = check('R{"steps"}max=? [F "decided"]', "MAXIMIZE")
    assert r.lower - 1e-9 <= task <= r.lower + 1e-7
    assert risk <= 0.1 and risk == pytest.approx(r.constraints[0].value, abs=1e-7)
    assert steps <= r.steps + 1e-9 and steps == pytest.approx(r.steps, abs=1e-7)
    assert json.loads(json.dumps(r.summary(), default=repr))["robust"]

"""The one DRN writer (mitld_lp.files.drn): its text against a line-by-line reference
written here from the format's description, and its files read back by Storm (stormpy)
with values computed by hand: rewards (exact, Storm's rational engine), intervals, a
DTMC, a declared label no state carries, and the merged model of a constrained
synthesis checked by Storm's multi-objective engine."""

from __future__ import annotations

from dataclasses import replace
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.files import drn
from mitld_lp.files.drn import DrnModel, Reward
from mitld_lp.mdp import ABSORB
from mitld_lp.testing import random_mdp


def reference_text(model: DrnModel) -> str:
    """The file, one line at a time, from the format's description (module docstring of
    mitld_lp.files.drn), over a dense copy of the matrix."""
    n = model.n_states
    carried = {name for name, mask in model.labels if np.any(mask)}
    missing = [name for name in model.declared if name not in carried]
    lines = [f"// {model.comment}"] if model.comment else []
    lines += [f"@type: {model.kind}", "@parameters", "", "@reward_models",
              " ".join(r.name for r in model.rewards), "@nr_states", str(n + bool(missing)),
              "@nr_choices", str(model.n_choices + bool(missing)), "@model"]
    low = model.matrix.toarray()
    high = low.copy()
    if model.upper is not None:  # the upper ends, entry by entry of the CSR storage
        rows = np.repeat(np.arange(model.n_choices), np.diff(model.matrix.indptr))
        high[rows, model.matrix.indices] = model.upper

    def bracket(values: list) -> str:
        return " [" + ", ".join(repr(v) for v in values) + "]"

    state_r = [r for r in model.rewards if r.state is not None]
    choice_r = [r for r in model.rewards if r.choice is not None]
    for s in range(n + bool(missing)):
        real = s < n
        words = [f"state {s}"]
        if state_r:
            words[0] += bracket([0 if r.state is None else r.state[s].item() if real else
                                 r.state.dtype.type(0).item() for r in model.rewards])
        if real:
            words += ["init"] * (s == model.initial) + [
                name for name, mask in model.labels if mask[s]]
        else:
            words += missing
        lines.append(" ".join(words))
        if model.valuations is not None:
            lines.append(f"//[{model.valuations[s]}]" if real else
                         f"//[unreachable: declares the label{'s' * (len(missing) > 1)}]")
        choices = range(model.row_groups[s], model.row_groups[s + 1]) if real else [None]
        for k, c in enumerate(choices):
            if model.action_names is None:
                name = str(k)
            else:
                a = ABSORB if c is None else int(model.choice_actions[c])
                name = "absorb" if a == ABSORB else "_".join(model.action_names[a].split())
            line = f"\taction {name}"
            if choice_r:
                line += bracket([0 if r.choice is None else r.choice[c].item() if real else
                                 r.choice.dtype.type(0).item() for r in model.rewards])
            lines.append(line)
            if c is None:
                lines.append(f"\t\t{s} : " + ("1.0" if model.upper is None else "[1.0, 1.0]"))
                continue
            for t in np.flatnonzero(high[c] > 0):
                p = repr(float(low[c, t])) if model.upper is None else \
                    f"[{float(low[c, t])!r}, {float(high[c, t])!r}]"
                lines.append(f"\t\t{t} : {p}")
    return "\n".join(lines) + "\n"


def shuffled(matrix: sp.csr_array, seed: int) -> sp.csr_array:
    """``matrix`` with each row's entries stored out of order and one explicit zero."""
    rng = np.random.default_rng(seed)
    coo = matrix.tocoo()
    zero_row = int(rng.integers(matrix.shape[0]))
    free = np.setdiff1d(np.arange(matrix.shape[1]), coo.col[coo.row == zero_row])
    rows = np.append(coo.row, zero_row)
    cols = np.append(coo.col, free[0])
    vals = np.append(coo.data, 0.0)
    order = np.lexsort((rng.random(rows.size), rows))  # by row, at random inside one
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=matrix.shape[0]))])
    return sp.csr_array((vals[order], cols[order], indptr), shape=matrix.shape)


def full_model(seed: int, *, named: bool, interval: bool, empty_goal: bool) -> DrnModel:
    """A random model with every part the format has."""
    rng = np.random.default_rng(seed)
    mdp = random_mdp(40, seed=seed, locality=4 if seed % 2 else None)
    matrix = shuffled(mdp.matrix, seed)
    n, m = mdp.n_states, mdp.n_choices
    goal = np.zeros(n, bool) if empty_goal else np.asarray(mdp.target)
    upper = None
    if interval:  # some lower ends 0 (kept), the explicit zero's upper end 0 (left out)
        upper = np.minimum(1.0, matrix.data * 1.5)
        matrix = sp.csr_array((np.where(np.arange(matrix.nnz) % 4 == 0, 0.0,
                                        matrix.data * 0.6), matrix.indices, matrix.indptr),
                              shape=matrix.shape)
    return DrnModel(
        matrix=matrix, row_groups=mdp.row_groups, initial=int(rng.integers(n)),
        labels=(("goal", goal), ("odd", np.arange(n) % 2 == 1), ("sink", mdp.sink)),
        declared=("goal", "never"),
        action_names=tuple(f"go {a}" for a in mdp.action_names) if named else None,
        choice_actions=mdp.choice_actions if named else None,
        upper=upper,
        valuations=tuple(f"x={s} & y={s % 3}" for s in range(n)),
        rewards=(Reward("time", state=rng.random(n)),
                 Reward("cost", choice=rng.integers(0, 5, m)),
                 Reward("both", state=rng.integers(0, 3, n), choice=rng.random(m))),
        comment="a test")


@pytest.mark.parametrize("seed", range(4))
def test_the_text_is_the_reference_whatever_the_chunk(seed: int, tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    model = full_model(seed, named=seed % 2 == 0, interval=seed >= 2, empty_goal=seed == 1)
    want = reference_text(model)
    for chunk in (drn.CHUNK_STATES, 7, 1):
        monkeypatch.setattr(drn, "CHUNK_STATES", chunk)
        path = drn.write(model, tmp_path / f"{chunk}.drn")
        assert path.read_text(encoding="utf-8") == want, chunk


def hand_mdp(**more: object) -> DrnModel:
    """State 0: action ``a`` to 1 or 2 (1/2 each), action ``b`` to 2; state 1 to 2;
    state 2, ``goal``, loops.  Rewards ``time`` (1 in state 0, 2 in state 1) and
    ``cost`` (3 for ``a``, 10 for ``b``, 4 for state 1's choice)."""
    matrix = sp.csr_array(np.array([[0, 0.5, 0.5], [0, 0, 1.0], [0, 0, 1.0], [0, 0, 1.0]]))
    fields: dict = dict(
        matrix=matrix, row_groups=np.array([0, 2, 3, 4]), initial=0,
        labels=(("goal", np.array([False, False, True])),), declared=("goal", "never"),
        action_names=("a", "b", "stay"), choice_actions=np.array([0, 1, 2, 2]),
        rewards=(Reward("time", state=np.array([1.0, 2.0, 0.0])),
                 Reward("cost", choice=np.array([3, 10, 4, 0]))))
    fields.update(more)
    return DrnModel(**fields)


def test_rewards_read_back_by_storm_exactly(tmp_path: Path) -> None:
    """By hand: time is 1 + (1/2)2 = 2 by ``a``, 1 by ``b``; cost 3 + (1/2)4 = 5 by
    ``a``, 10 by ``b``; ``never`` is on no state but declared: reaching it is 0."""
    stormpy = pytest.importorskip("stormpy")
    path = drn.write(hand_mdp(), tmp_path / "r.drn")
    model = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    assert model.nr_states == 4  # the three, and the one declaring "never"
    want = {'R{"time"}min=? [F "goal"]': 1, 'R{"time"}max=? [F "goal"]': 2,
            'R{"cost"}min=? [F "goal"]': 5, 'R{"cost"}max=? [F "goal"]': 10,
            'Pmax=? [F "never"]': 0, 'Pmin=? [F "goal"]': 1}
    for prop, value in want.items():
        result = stormpy.model_checking(model, stormpy.parse_properties(prop)[0])
        assert Fraction(str(result.get_value(model.initial_states[0]))) == value, prop


def test_intervals_read_back_by_storm(tmp_path: Path) -> None:
    """From state 0: goal in [0.2, 0.4], fail in [0.3, 0.5], back to 0 in [0.2, 0.4].
    The chance of reaching goal is g / (g + f): nature's worst (g = 0.2, f = 0.5, stay
    0.3) gives 2/7, its best (g = 0.4, f = 0.3) 4/7.  As a DTMC the file is read with
    each interval where it was written."""
    stormpy = pytest.importorskip("stormpy")
    matrix = sp.csr_array((np.array([0.2, 0.2, 0.3, 1.0, 1.0]), np.array([0, 1, 2, 1, 2]),
                           np.array([0, 3, 4, 5])), shape=(3, 3))
    chain = DrnModel(matrix=matrix, row_groups=np.arange(4), initial=0, kind="DTMC",
                     upper=np.array([0.4, 0.4, 0.5, 1.0, 1.0]),
                     labels=(("goal", np.array([False, True, False])),), declared=("goal",))
    read = stormpy.build_model_from_drn[stormpy.Interval](str(drn.write(chain,
                                                                        tmp_path / "c.drn")))
    assert read.model_type.name == "DTMC"
    got = {(row, e.column): (e.value.lower(), e.value.upper())
           for row in range(3) for e in read.transition_matrix.get_row(row)}
    assert got == {(0, 0): (0.2, 0.4), (0, 1): (0.2, 0.4), (0, 2): (0.3, 0.5),
                   (1, 1): (1.0, 1.0), (2, 2): (1.0, 1.0)}
    mdp = stormpy.build_model_from_drn[stormpy.Interval](str(drn.write(
        replace(chain, kind="MDP"), tmp_path / "m.drn")))
    env = stormpy.Environment()
    env.solver().min_max().precision = stormpy.Rational("1/1000000000000")
    prop = stormpy.parse_properties('Pmax=? [F "goal"]')[0]
    for mode, want in (("ROBUST", 2 / 7), ("COOPERATIVE", 4 / 7)):
        result = stormpy.model_checking(
            mdp, prop, environment=env,
            uncertainty_resolution_mode=getattr(stormpy.UncertaintyResolutionMode, mode))
        assert result.get_value(mdp.initial_states[0]) == pytest.approx(want, abs=1e-9)


@pytest.mark.parametrize(("change", "words"), [
    (dict(kind="DTMC"), "one choice per state"),
    (dict(kind="CTMC"), "neither MDP nor DTMC"),
    (dict(labels=(("two words", np.zeros(3, bool)),)), "not one token"),
    (dict(labels=(("goal", np.zeros(4, bool)),)), "label 'goal'"),
    (dict(choice_actions=None), "go together"),
    (dict(upper=np.ones(2)), "upper"),
    (dict(valuations=("x=0",)), "1 valuations for 3 states"),
    (dict(rewards=(Reward("r", choice=np.ones(3)),)), "reward 'r'"),
    (dict(rewards=(Reward("r", state=np.ones(3, bool)),)), "not numbers"),
    (dict(initial=3), "initial state 3"),
])
def test_a_model_the_format_cannot_say_is_refused(change: dict, words: str) -> None:
    with pytest.raises(ValueError, match=words):
        hand_mdp(**change)


def test_the_merged_model_checks_in_storms_multi_objective_engine(tmp_path: Path) -> None:
    """The constrained export's own file (routes.constrained_export) with the property
    its docstring names: Storm's multi-objective optimum is the synthesis's value, with
    a risk bound and with a steps bound on the ``steps`` reward."""
    stormpy = pytest.importorskip("stormpy")
    import stormpy.environments as env_mod

    from mitld_lp.model import load_model
    from mitld_lp.routes.constrained_export import write_merged_drn
    from mitld_lp.synthesis import synthesize_constrained

    model = load_model(Path(__file__).resolve().parent.parent / "models" / "bus_risk.toml")
    env = stormpy.Environment()
    multi = env.modelchecker().multi()
    multi.precision = stormpy.Rational("1/1000000000")
    multi.precision_type = env_mod.MultiObjectivePrecisionType.ABSOLUTE
    free = synthesize_constrained(model, ["P(F puddle) <= 0.05"])
    steps = round(free.steps - 0.2, 3)  # binds: the optimum needs more steps
    for bounds, query in ((["P(F puddle) <= 0.05"], 'multi(Pmax=? [F "target"], '
                                                   'P<=0.05 [F "c1"])'),
                          (["P(F puddle) <= 0.05", f"E(steps) <= {steps}"],
                           f'multi(Pmax=? [F "target"], P<=0.05 [F "c1"], '
                           f'R{{"steps"}}<={steps} [C])')):
        r = synthesize_constrained(model, bounds)
        assert r.status == "optimal" and r.certified
        path = write_merged_drn(r.merged, tmp_path / f"m{len(bounds)}.drn", overwrite=True)
        read = stormpy.build_model_from_drn(str(path))
        result = stormpy.model_checking(read, stormpy.parse_properties(query)[0],
                                        environment=env)
        assert r.lower == pytest.approx(result.get_value(read.initial_states[0]), abs=1e-6)
    assert r.lower < free.lower - 1e-4  # the steps bound binds


def test_a_constraint_no_state_meets_is_still_a_label_storm_knows(tmp_path: Path) -> None:
    """``P(F (A & B))``: A and B are different cells, so no state carries ``c1``.  The
    file still declares it (the merged model's writer before the one writer did not, and
    Storm refused the property with "unknown label 'c1'"): reaching it is 0 by hand, and
    the constraint does not bind, so Storm's multi-objective optimum is Pmax of the
    target alone on the same file."""
    stormpy = pytest.importorskip("stormpy")
    import stormpy.environments as env_mod

    from mitld_lp.automata.joint import ACCEPTED
    from mitld_lp.model import load_model
    from mitld_lp.routes.constrained_export import write_merged_drn
    from mitld_lp.synthesis import synthesize_constrained

    model = load_model(Path(__file__).resolve().parent.parent / "models" / "bus_risk.toml")
    r = synthesize_constrained(model, ["P(F (A & B)) <= 0.1"])
    assert not np.any(r.merged.verdicts[:, 1] == ACCEPTED)
    read = stormpy.build_model_from_drn(str(write_merged_drn(r.merged, tmp_path / "m.drn")))
    env = stormpy.Environment()
    env.modelchecker().multi().precision = stormpy.Rational("1/1000000000")
    env.modelchecker().multi().precision_type = \
        env_mod.MultiObjectivePrecisionType.ABSOLUTE

    def value(prop: str) -> float:
        result = stormpy.model_checking(read, stormpy.parse_properties(prop)[0],
                                        environment=env)
        return result.get_value(read.initial_states[0])

    assert value('Pmax=? [F "c1"]') == 0
    both = value('multi(Pmax=? [F "target"], P<=0.1 [F "c1"])')
    assert both == pytest.approx(value('Pmax=? [F "target"]'), abs=1e-6)
    assert r.lower == pytest.approx(both, abs=1e-6)

"""The compiled sweeps' guessed and verified bounds (mitld_lp.solvers.kernels) on blocks
that mix slowly: a ring the walk leaves once in thousands of steps.  Expected values
from independent routes: a closed form (a symmetric ring: every state's value is its
best choice's odds of the goal against the fail state) and Storm's exact engine on the
same ring written as a PRISM file."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import MDP
from mitld_lp.solvers import Status, interval_iteration
from mitld_lp.solvers import kernels as kernels_module

pytestmark = pytest.mark.skipif(kernels_module.compiled_kernel() is None,
                                reason="numba is not installed")

# per choice: (steps along the ring with their probabilities), goal, fail (exact decimals)
Choice = tuple[tuple[tuple[int, str], ...], str, str]


def _ring(n: int, choices: list[list[Choice]]) -> tuple[MDP, str]:
    """The ring of ``n`` states (state ``i`` has ``choices[i]``) with a goal ``n`` and a
    fail state ``n + 1``, as an MDP and as PRISM text (the same decimals)."""
    rows, cols, vals, groups, actions = [], [], [], [0], []
    lines = ["mdp", "module m", f"  s : [0..{n + 1}] init 0;"]
    for i in range(n):
        for k, (steps, goal, fail) in enumerate(choices[i]):
            row = len(actions)
            branches = []
            for step, p in steps:
                rows.append(row), cols.append((i + step) % n), vals.append(float(p))
                branches.append(f"{p} : (s'={(i + step) % n})")
            for t, p in ((n, goal), (n + 1, fail)):
                rows.append(row), cols.append(t), vals.append(float(p))
                branches.append(f"{p} : (s'={t})")
            actions.append(k)
            lines.append(f"  [c{k}] s={i} -> {' + '.join(branches)};")
        groups.append(len(actions))
    for t in (n, n + 1):  # absorbing
        rows.append(len(actions)), cols.append(t), vals.append(1.0)
        actions.append(-1)
        groups.append(len(actions))
    lines += [f"  [] s>={n} -> true;", "endmodule", f'label "goal" = s={n};']
    matrix = sp.csr_array((vals, (rows, cols)), shape=(len(actions), n + 2))
    target = np.zeros(n + 2, dtype=bool)
    sink = np.zeros(n + 2, dtype=bool)
    target[n], sink[n + 1] = True, True
    mdp = MDP(matrix=matrix, row_groups=np.array(groups, dtype=np.int64),
              choice_actions=np.array(actions, dtype=np.int32), action_names=("c0", "c1"),
              initial=0, target=target, sink=sink, truncated=np.zeros(n + 2, dtype=bool),
              states=tuple(range(n + 2)))
    return mdp, "\n".join(lines) + "\n"


def _solve(mdp: MDP, optimistic: bool, monkeypatch, **kw) -> object:
    monkeypatch.setattr(kernels_module, "OPTIMISTIC", optimistic)
    return interval_iteration(mdp, mdp.target, gap="max", progress=False, compiled=True,
                              precision=None, **kw)


SYMMETRIC: list[Choice] = [
    (((1, "0.5"), (-1, "0.497")), "0.0018", "0.0012"),  # odds 0.6
    (((2, "0.3"), (-3, "0.6976")), "0.0015", "0.0009"),  # odds 0.625: the best
]


def _uneven(n: int) -> list[list[Choice]]:
    """A ring whose exits differ from state to state (values that vary along it), every
    fourth state with one choice only; probabilities in units of 1e-3."""
    out = []
    for i in range(n):
        g, f = 1 + i % 7, 1 + (3 * i) % 5
        first = (((1, "0.6"), (-1, f"0.{400 - g - f:03d}")), f"0.{g:03d}", f"0.{f:03d}")
        second = (((3, "0.25"), (-2, "0.747")), "0.002", "0.001")
        out.append([first, second] if i % 4 else [first])
    return out


def _storm_values(text: str, tmp_path: Path) -> np.ndarray:
    """Storm's exact Pmax(F goal) of every state ``s`` of the PRISM text."""
    stormpy = pytest.importorskip("stormpy")
    path = tmp_path / "ring.prism"
    path.write_text(text)
    program = stormpy.parse_prism_program(str(path))
    props = stormpy.parse_properties('Pmax=? [F "goal"]', program)
    options = stormpy.BuilderOptions()
    options.set_build_state_valuations()
    options.set_build_all_labels()
    model = stormpy.build_model[stormpy.Rational](program, options=options)
    env = stormpy.Environment()
    env.solver().force_exact = True
    result = stormpy.model_checking(model, props[0], environment=env)
    values = np.zeros(model.nr_states)
    for state in range(model.nr_states):  # Storm numbers them in its own order
        i = json.loads(str(model.state_valuations.to_json(state)))["s"]
        values[i] = float(Fraction(str(result.get_value(state))))
    return values


def _ring_block(mdp: MDP):
    """The ring's block of the quotient and its exits (the goal's one-step
    probabilities), for the kernel's own calls."""
    from mitld_lp.solvers.quotient import quotient_for
    from mitld_lp.solvers.topological import Block, blocks

    q = quotient_for(mdp, mdp.target, None, kernels_module.Sense.MAX)
    blk = blocks(q)
    states = np.flatnonzero(blk.size[blk.component] > 1)
    block = Block.of(q, states)
    return q, states, block, np.repeat(q.to_target[block.choices][:, None], 2, axis=1)


def _kernel(block, exits, n: int, optimistic: bool, monkeypatch, chunk: int,
            check=None) -> tuple[int, float, object]:
    """The block swept by the compiled kernel from ``[0, 1]``, ``chunk`` sweeps a call
    (``check(local)`` after each); the sweeps, the last gap over ``tol`` and the
    kernel's state."""
    monkeypatch.setattr(kernels_module, "OPTIMISTIC", optimistic)
    prep = kernels_module.Prepared(block.inner, block.groups)
    local = np.column_stack([np.zeros(n), np.ones(n)])
    done, over = 0, np.inf
    while over >= 1.0 and done < 20_000:
        swept, over = kernels_module.compiled_sweeps(prep, exits, local, 1e-9, chunk)
        done += swept
        if check is not None:
            check(local)
    return done, over, prep


@pytest.mark.parametrize("n", [6, 10])
def test_a_symmetric_ring_closes_on_its_closed_form_in_fewer_sweeps(monkeypatch,
                                                                    n: int) -> None:
    # every state alike: the optimum is the best choice's goal / (goal + fail) = 5/8
    mdp, _ = _ring(n, [SYMMETRIC] * n)
    _, states, block, exits = _ring_block(mdp)
    assert states.size == n

    def check(local: np.ndarray) -> None:
        assert np.all(local[:, 0] <= 0.625) and np.all(0.625 <= local[:, 1])

    plain, over_plain, _ = _kernel(block, exits, n, False, monkeypatch, 16, check)
    guessed, over, prep = _kernel(block, exits, n, True, monkeypatch, 16, check)
    assert over_plain < 1.0 and over < 1.0
    # the plain sweeps close by 0.996 a sweep (some 4,700 sweeps)
    assert guessed < plain / 4
    assert prep.track[2] >= 1 and prep.track[3] >= 2  # guesses made, both sides proven
    r = _solve(mdp, True, monkeypatch)
    assert r.status == Status.OPTIMAL
    assert np.all(r.lower[:n] <= 0.625) and np.all(0.625 <= r.upper[:n])
    assert float(np.max(r.upper - r.lower)) < 1e-9


@pytest.mark.parametrize("chunk", [1, 5, 16])
def test_an_uneven_ring_stays_around_storms_exact_values_after_every_call(
        monkeypatch, tmp_path: Path, chunk: int) -> None:
    # stopped after any sweep, a guess on trial included, the bounds are proven ones
    n = 10
    mdp, text = _ring(n, _uneven(n))
    exact = _storm_values(text, tmp_path)
    q, states, block, exits = _ring_block(mdp)
    assert states.size == n

    def check(local: np.ndarray) -> None:
        full = np.zeros((q.n_states, 2))
        full[states] = local
        lower, upper = q.lift(full[:, 0])[:n], q.lift(full[:, 1])[:n]
        assert np.all(lower <= exact[:n] + 1e-15) and np.all(exact[:n] <= upper + 1e-15)

    plain, _, _ = _kernel(block, exits, n, False, monkeypatch, chunk)
    guessed, over, _ = _kernel(block, exits, n, True, monkeypatch, chunk, check)
    assert over < 1.0 and guessed < plain / 4


@pytest.mark.parametrize("budget", [7, 40, 150, 1_000_000])
def test_an_uneven_ring_brackets_storms_exact_values_at_every_budget(
        monkeypatch, tmp_path: Path, budget: int) -> None:
    n = 30
    mdp, text = _ring(n, _uneven(n))
    exact = _storm_values(text, tmp_path)[:n]
    r = _solve(mdp, True, monkeypatch, max_iterations=budget)
    assert np.all(r.lower[:n] <= exact + 1e-15) and np.all(exact <= r.upper[:n] + 1e-15)
    if budget == 1_000_000:
        assert r.status == Status.OPTIMAL
        assert float(np.max(r.upper[:n] - r.lower[:n])) < 1e-9

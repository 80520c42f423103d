"""Shared pytest configuration (a deterministic hypothesis profile for CI) and the small
hand-built MDPs the solver tests share (``from conftest import HAND, build_mdp``), and
Pmax by the classic value LP (``reference_values``), a route that shares nothing with
the package's solvers."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

import numpy as np
import scipy.optimize
import scipy.sparse as sp
from hypothesis import HealthCheck, settings

from mitld_lp.mdp import ABSORB, MDP

settings.register_profile(
    "ci",
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile("dev", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("ci" if os.environ.get("CI") else "dev")


def build_mdp(
    choices: Sequence[Sequence[tuple[str, Mapping[int, float]]]],
    *,
    initial: int = 0,
    target: Sequence[int] = (),
    sink: Sequence[int] = (),
    truncated: Sequence[int] = (),
) -> MDP:
    """An :class:`MDP` from per-state lists of ``(action name, {successor: probability})``.

    A state listed in ``target``, ``sink`` or ``truncated`` with no choices gets the
    ``ABSORB`` self-loop.  Rows must sum to 1 (checked to 1e-12).  States are numbered
    by position; ``states`` holds those numbers.
    """
    n = len(choices)
    absorbing = set(target) | set(sink) | set(truncated)
    names: dict[str, int] = {}
    rows: list[int] = []
    cols: list[int] = []
    vals: list[float] = []
    actions: list[int] = []
    groups = [0]
    for s, state_choices in enumerate(choices):
        todo: list[tuple[str, Mapping[int, float]]] = list(state_choices)
        base = len(actions)
        if not todo:
            if s not in absorbing:
                raise ValueError(f"state {s}: no choices and not absorbing")
            todo = [("", {s: 1.0})]
            actions.append(ABSORB)
        else:
            actions.extend(names.setdefault(a, len(names)) for a, _ in todo)
        for j, (name, dist) in enumerate(todo):
            total = sum(dist.values())
            if abs(total - 1.0) > 1e-12 or any(p < 0 for p in dist.values()):
                raise ValueError(f"state {s}, action {name!r}: not a distribution {dist}")
            for t, p in dist.items():
                if not 0 <= t < n:
                    raise ValueError(f"state {s}, action {name!r}: no state {t}")
                rows.append(base + j)
                cols.append(t)
                vals.append(float(p))
        groups.append(len(actions))
    m = len(actions)
    matrix = sp.csr_array((vals, (rows, cols)), shape=(m, n))

    def mask(idx: Sequence[int]) -> np.ndarray:
        out = np.zeros(n, dtype=bool)
        out[list(idx)] = True
        return out

    return MDP(
        matrix=matrix,
        row_groups=np.asarray(groups, dtype=np.int64),
        choice_actions=np.asarray(actions, dtype=np.int32),
        action_names=tuple(names),
        initial=initial,
        target=mask(target),
        sink=mask(sink),
        truncated=mask(truncated),
        states=tuple(range(n)),
    )


# 0: 'stay' self-loop | 'go' -> 1 or 2           (0 alone is an end component)
# 1: 'a' -> 3 (target) or 0 | 'b' -> 4           (1, 4 form a MEC with exits a, d)
# 2: sink   3: target
# 4: 'c' -> 1 | 'd' -> 3 or 2
# 5: 'e' -> 2 only                               (prob 0, not absorbing)
# 6: 'f' -> 6 or 3 | 'g' -> 2                    (prob 1 by f)
# By hand:  v(1) = v(4) = max(0.3 + 0.7 v(0), 0.5),  v(0) = max(v(0), 0.5 v(1));
# with 'a': v(1) = 0.3 / 0.65 < 0.5, so 'd': v(1) = v(4) = 1/2, v(0) = 1/4;  v(6) = 1.
HAND_CHOICES: list[list[tuple[str, dict[int, float]]]] = [
    [("stay", {0: 1.0}), ("go", {1: 0.5, 2: 0.5})],
    [("a", {3: 0.3, 0: 0.7}), ("b", {4: 1.0})],
    [],
    [],
    [("c", {1: 1.0}), ("d", {3: 0.5, 2: 0.5})],
    [("e", {2: 1.0})],
    [("f", {6: 0.5, 3: 0.5}), ("g", {2: 1.0})],
]
HAND = build_mdp(HAND_CHOICES, target=[3], sink=[2])
HAND_VALUES = np.array([0.25, 0.5, 0.0, 1.0, 0.5, 0.0, 1.0])


def reference_values(mdp: MDP, target: np.ndarray) -> np.ndarray:
    """Pmax by the value LP on the raw MDP (scipy linprog / HiGHS): ``min sum v`` s.t.
    ``v(s) >= sum P(c,.) v`` for every choice ``c`` of ``s``, ``v(target) = 1``,
    ``0 <= v <= 1``, no graph analysis and no end-component collapse; its least
    solution is Pmax."""
    n = mdp.n_states
    dense = mdp.matrix.toarray()
    owner = mdp.choice_state()
    rows = np.flatnonzero(~target[owner])
    a_ub = dense[rows] - np.eye(n)[owner[rows]]  # P(c,.) v - v(s) <= 0
    bounds = [(1.0, 1.0) if target[s] else (0.0, 1.0) for s in range(n)]
    res = scipy.optimize.linprog(
        np.ones(n), A_ub=a_ub, b_ub=np.zeros(rows.size), bounds=bounds, method="highs",
        options={"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10},
    )
    assert res.status == 0, res.message
    return np.asarray(res.x)

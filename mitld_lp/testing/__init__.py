"""Helpers shared by the tests and the benchmarks, which may not import each other:
random MDPs (the benchmarks' "random local MDP"), the state-at-a-time reference product
(:mod:`mitld_lp.testing.reference_product`) and the fuzzing generators
(:mod:`mitld_lp.testing.fuzz`).  Not used by the library.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.testing.reference_product import reference_product
from mitld_lp.worlds.game import ExplicitGame

__all__ = ["random_mdp", "reference_product", "two_routes_world"]


def two_routes_world() -> ExplicitGame:
    """A world worked by hand in the tests: from ``s0``, ``safe`` reaches the goal with
    1/2; ``risky`` with 0.9, but 0.3 of it through a hazard (state ``hg``, labelled goal
    and hazard)."""
    return ExplicitGame(
        initial="s0",
        transitions={
            "s0": {"safe": {"goal": 0.5, "trap": 0.5},
                   "risky": {"hg": 0.3, "goal": 0.6, "trap": 0.1}},
            "goal": {"wait": {"goal": 1.0}},
            "trap": {"wait": {"trap": 1.0}},
            "hg": {"wait": {"hg": 1.0}},
        },
        labels={"goal": {"goal"}, "hg": {"goal", "hazard"}},
        proposition_names=frozenset({"goal", "hazard"}),
    )


def random_mdp(
    n_states: int,
    *,
    seed: int,
    max_choices: int = 4,
    max_successors: int = 4,
    target_fraction: float = 0.05,
    sink_fraction: float = 0.05,
    self_loop_fraction: float = 0.1,
    locality: int | None = None,
) -> MDP:
    """A random MDP for tests and benchmarks (vectorised; 1e6 states in seconds).

    State 0 is initial.  About ``target_fraction`` / ``sink_fraction`` of the other
    states are absorbing target / sink states.  Every other state has 1..``max_choices``
    choices, each with 1..``max_successors`` successors (duplicates merged) and random
    probabilities; a fraction ``self_loop_fraction`` of the choices are pure self-loops
    (end components).  With ``locality`` the successors are drawn within that distance
    of the state (long chains, many end components).
    """
    rng = np.random.default_rng(seed)
    n = n_states
    kind = rng.random(n)
    target = kind < target_fraction
    sink = (kind >= target_fraction) & (kind < target_fraction + sink_fraction)
    target[0] = sink[0] = False
    absorbing = target | sink
    n_ch = np.where(absorbing, 1, rng.integers(1, max_choices + 1, size=n))
    groups = np.concatenate([[0], np.cumsum(n_ch)]).astype(np.int64)
    m = int(groups[-1])
    owner = np.repeat(np.arange(n), n_ch)
    n_succ = rng.integers(1, max_successors + 1, size=m)
    loop = (rng.random(m) < self_loop_fraction) | absorbing[owner]
    n_succ[loop] = 1
    row = np.repeat(np.arange(m), n_succ)
    if locality is None:
        col = rng.integers(0, n, size=row.size)
    else:
        col = np.clip(owner[row] + rng.integers(-locality, locality + 1, size=row.size),
                      0, n - 1)
    col[loop[row]] = owner[row][loop[row]]
    weight = rng.random(row.size) + 0.05
    matrix = sp.csr_array((weight, (row, col)), shape=(m, n))
    matrix.sum_duplicates()
    sums = np.asarray(matrix.sum(axis=1)).ravel()
    matrix = sp.csr_array(sp.diags_array(1.0 / sums) @ matrix)
    actions = (np.arange(m) - groups[owner]).astype(np.int32)
    actions[absorbing[owner]] = ABSORB
    return MDP(
        matrix=matrix,
        row_groups=groups,
        choice_actions=actions,
        action_names=tuple(f"a{i}" for i in range(max_choices)),
        initial=0,
        target=target,
        sink=sink,
        truncated=np.zeros(n, dtype=bool),
        states=tuple(range(n)),
    )

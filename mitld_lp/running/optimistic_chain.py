"""The controlled chain of an optimistic answer (a band read for its best law,
``bands = "best"``, no constraints): a plain Markov chain at nature's chosen law.

The optimistic answer is a pair: the robot's policy and the law of the bands that
helps it most (nature's vertex row of each of the robot's choices, at every step).  Its
controller is the robot's half, so its claim is about that law only: the chain here is
the controller run at the law, on which Storm's ``P=? [F "accept"]`` is at least
``lower`` -- the interval chain of :mod:`mitld_lp.running.band_chain` would claim a worst
case, which an optimistic controller does not bound.

Nature's half is found again from the policy's values (the answer keeps the robot's
choice of each state): on the interval MDP with the robot's choices fixed, each of its
vertex rows a choice of nature's, the rows within a tie of the best against the values,
and among them one by which the state enters the positive attractor of the task's goal
(:func:`mitld_lp.solvers.robust.robust_policy`, as the answer's own policy was read), so
that no loop the values alone would allow keeps the run from the goal.  Every other
robot choice is at the middle law of the bands (it is never taken).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.product.imdp import IntervalMDP, point_mdp, vertex_rows
from mitld_lp.running.chain import controlled_chain
from mitld_lp.running.chain_model import Chain

__all__ = ["is_optimistic", "optimistic_chain_of", "optimistic_claim"]


def is_optimistic(result: Any) -> bool:
    """Whether ``result`` is a robust answer with the bands read for their best law."""
    part = getattr(result, "part", None)
    return bool(getattr(part, "interval", False)) and getattr(part, "reading", "") == "best"


def nature_rows(result: Any) -> sp.csr_array:
    """Per choice of the answer's interval MDP, its row at nature's chosen law (module
    docstring): the chosen vertex row for the robot's choice of each state, the middle
    law for any other."""
    from mitld_lp.product.imdp import middle_rows
    from mitld_lp.solvers.robust import robust_policy
    from mitld_lp.solvers.robust_graph import cooperative, robust_game

    imdp = result.mdp
    assert isinstance(imdp, IntervalMDP)
    solution = result.part.lower_model
    policy = np.asarray(solution.policy, dtype=np.int64)
    fixed = np.where(policy >= 0, policy, np.asarray(imdp.row_groups[:-1], dtype=np.int64))
    game = robust_game(imdp).restrict(fixed)  # the robot's choices fixed; nature's rows
    rows = robust_policy(cooperative(game), np.asarray(result.part.goal, dtype=bool),
                         np.asarray(solution.policy_values, dtype=np.float64), tie=1e-12)
    vr = vertex_rows(imdp)
    vertex = vr.groups[fixed] + (rows - game.vertex_groups[:-1])  # the row's vertex index
    n = imdp.n_choices
    put = sp.csr_array((np.ones(fixed.size), (fixed, np.arange(fixed.size))),
                       shape=(n, fixed.size))
    other = np.ones(n)
    other[fixed] = 0.0
    out = sp.csr_array(sp.diags_array(other) @ middle_rows(imdp) + put @ vr.matrix[vertex])
    out.eliminate_zeros()
    out.sort_indices()
    return out


def optimistic_chain_of(result: Any) -> Chain:
    """The controlled chain of the module docstring."""
    if not is_optimistic(result):
        raise ValueError("not an answer with the bands read for their best law")
    law = point_mdp(result.mdp, nature_rows(result))
    return controlled_chain(law, result.controller, result.dta.persistent, result.model.game)


def optimistic_claim(result: Any) -> tuple[float, str]:
    """What Storm's check of the chain gives, against ``result``'s bracket: the bound and
    the sentence the command line prints."""
    if result.complemented:
        bound = result.complement[0] if result.complement is not None else 1 - result.upper
        return bound, (f"P=? [F \"accept\"] >= the complement's lower = {bound!r}, at "
                       "nature's chosen law: for a minimised task \"accept\" marks the runs "
                       "that fail it")
    return result.lower, (f"P=? [F \"accept\"] >= lower = {result.lower!r}, at nature's "
                          "chosen law of the bands (a plain chain: an optimistic answer "
                          "claims nothing about other laws)")

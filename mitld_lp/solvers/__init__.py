"""Solvers for maximal (or minimal: ``sense=Sense.MIN``) reachability on a
:class:`mitld_lp.mdp.MDP`.

* :func:`solve_lp` -- the occupancy-measure LP (cvxpy with any installed LP solver, or
  Clarabel called directly), block by block in topological order by default
  (``layout=Layout.WHOLE``: one monolithic LP), its duals as the value function, and the
  policies;
* :func:`interval_iteration` -- sound lower / upper bounds by value iteration, also in
  topological order by default;
* :func:`evaluate_policy` -- the exact value of a deterministic policy;
* :func:`write_lp`, :func:`write_drn` -- exports for external solvers and Storm.

All of them start from :func:`mitld_lp.solvers.quotient.reduce`; pass its
:class:`~mitld_lp.solvers.quotient.Quotient` as ``quotient=`` to reduce a model once.
"""

from mitld_lp.solvers.evaluation import evaluate_policy
from mitld_lp.solvers.export import write_drn, write_lp
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import Layout, OccupancyLP, occupancy_lp, solve_lp
from mitld_lp.solvers.result import IterationResult, LPResult, Status

__all__ = [
    "IterationResult",
    "LPResult",
    "Layout",
    "OccupancyLP",
    "Sense",
    "Status",
    "evaluate_policy",
    "interval_iteration",
    "occupancy_lp",
    "solve_lp",
    "write_drn",
    "write_lp",
]

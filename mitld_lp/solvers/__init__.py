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

from __future__ import annotations

import importlib
import importlib.util
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the names' modules are imported on first use (__getattr__)
    from mitld_lp.solvers.evaluation import evaluate_policy
    from mitld_lp.solvers.export import write_drn, write_lp
    from mitld_lp.solvers.graph import Sense
    from mitld_lp.solvers.iteration import interval_iteration
    from mitld_lp.solvers.lp import Layout, OccupancyLP, occupancy_lp, solve_lp
    from mitld_lp.solvers.result import IterationResult, LPResult, Status

#: The public names and their modules: importing one solver module (the package runs
#: first) loads none of the others, nor the exports' writers (a solve does not export).
_WHERE = {"evaluate_policy": "evaluation", "write_drn": "export", "write_lp": "export",
          "Sense": "graph", "interval_iteration": "iteration", "Layout": "lp",
          "OccupancyLP": "lp", "occupancy_lp": "lp", "solve_lp": "lp",
          "IterationResult": "result", "LPResult": "result", "Status": "result"}


def __getattr__(name: str) -> Any:
    """A public name from its module, imported on first use (PEP 562)."""
    where = _WHERE.get(name)
    if where is None:  # a submodule, as the eager imports of old had loaded some
        if not name.startswith("__") and importlib.util.find_spec(f"{__name__}.{name}"):
            return importlib.import_module(f"{__name__}.{name}")
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{where}"), name)
    globals()[name] = value
    return value


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

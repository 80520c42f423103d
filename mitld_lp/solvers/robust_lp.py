r"""The robust value of a fixed robot policy as one linear program (Clarabel).

With the robot's choice fixed to ``sigma(s)``, only nature chooses: its value is the
*minimal* reach probability of an MDP whose actions are the vertex rows of ``sigma(s)``.
After the states where nature can avoid the target for ever are set to 0 (the complement
of the positive attractor of the restricted game), that MDP has no end component left
outside the target, and its value is the unique solution, hence the optimum, of

.. math::

    \max \sum_s V(s) \quad \text{s.t.}\quad
    V(s) \le P_v(\mathit{target}) + \sum_{s'} P_v(s')\, V(s')
    \ \ \text{for every vertex row } v \text{ of } \sigma(s), \qquad 0 \le V \le 1 .

A vertex constraint for every row is the inner minimum written exactly: ``V(s) <=
min_v P_v . V`` is ``V(s) <= P_v . V`` for each ``v`` (the rows are the vertices of the
hazard box; its other points are convex combinations in the value they give).

This certifies the policy's robust value from below: it is what the policy guarantees
against every adversary.  The robust optimum itself is a max-min; "``V(s) >= min_v P_v
. V`` for some choice" is not a convex constraint, and no single LP of this size gives
it (simple stochastic games are not known to be solvable in polynomial time); its upper
bound comes from the iteration (:mod:`.robust`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp import defaults
from mitld_lp.solvers.clarabel_lp import solve_clarabel
from mitld_lp.solvers.result import Status, read_only
from mitld_lp.solvers.robust_graph import RobustGame, positive_attractor

__all__ = ["PolicyLP", "policy_lp"]


@dataclass(frozen=True, slots=True, eq=False)
class PolicyLP:
    """The policy's robust value per state (``None`` without a solution), the number of
    variables and constraints, and the solver's status in its own words."""

    status: Status
    values: np.ndarray | None
    variables: int
    constraints: int
    message: str


def policy_lp(
    game: RobustGame,
    target: np.ndarray,
    policy: np.ndarray,
    *,
    tol: float = defaults.TOL,
    time_limit: float | None = None,
) -> PolicyLP:
    """The robust value of ``policy`` (a choice per state) by the LP of the module
    docstring, solved by Clarabel.  Every solver failure is a status."""
    target = np.asarray(target, dtype=bool)
    g = game.restrict(np.asarray(policy, dtype=np.int64))
    positive, _ = positive_attractor(g, target)
    unknown = positive & ~target
    values = np.where(target, 1.0, 0.0)
    n_var = int(unknown.sum())
    if n_var == 0:
        return PolicyLP(Status.OPTIMAL, read_only(values), 0, 0, "decided by the graph")
    index = np.full(g.n_states, -1, dtype=np.int64)
    index[unknown] = np.arange(n_var)
    row_state = g.row_state()
    rows = np.flatnonzero(unknown[row_state])
    m = g.matrix.tocoo()
    own = np.isin(m.row, rows)
    r, c, p = m.row[own], m.col[own], np.asarray(m.data, dtype=np.float64)[own]
    local_row = np.searchsorted(rows, r)
    to_target = np.bincount(local_row[target[c]], weights=p[target[c]], minlength=rows.size)
    keep = unknown[c]
    a = sp.csc_array(
        (np.concatenate([np.ones(rows.size), -p[keep]]),
         (np.concatenate([np.arange(rows.size), local_row[keep]]),
          np.concatenate([index[row_state[rows]], index[c[keep]]]))),
        shape=(rows.size, n_var),
    )
    eye = sp.eye_array(n_var, format="csc")
    a_all = sp.vstack([a, eye, -eye], format="csc")
    b_all = np.concatenate([to_target, np.ones(n_var), np.zeros(n_var)])
    settings: dict[str, Any] = {key: tol for key in ("tol_gap_abs", "tol_gap_rel", "tol_feas")}
    if time_limit is not None:
        settings["time_limit"] = max(float(time_limit), 1e-3)
    answer = solve_clarabel(-np.ones(n_var), a_all, b_all, zero=0,
                            nonneg=rows.size + 2 * n_var, settings=settings)
    if answer.x is None:
        return PolicyLP(answer.status, None, n_var, rows.size, answer.message)
    values[unknown] = np.clip(answer.x, 0.0, 1.0)
    return PolicyLP(answer.status, read_only(values), n_var, rows.size,
                    f"{answer.message} ({n_var} variables, {rows.size} vertex rows)")

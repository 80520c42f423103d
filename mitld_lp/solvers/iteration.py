r"""Interval iteration for maximal reachability, and exact evaluation of a policy.

Interval iteration (Haddad & Monmege, TCS 2018; Baier et al., CAV 2017) runs the
Bellman operator

.. math::

    (T x)(s) = \max_{c \in \mathit{Act}(s)} \hat P(c, \mathit{target})
               + \sum_{s'} \hat P(c, s')\, x(s')

on the MEC quotient (:func:`mitld_lp.mdp.reduce`) from two starting points: ``x = 0``
(increases to the optimum from below) and ``x = 1`` on the maybe states (decreases to it
from above; this needs the quotient: on an MDP with end components the upper sequence
can get stuck above the optimum).  Both vectors are updated together with one sparse
product and a segmented maximum (``np.maximum.reduceat`` on the row groups).
"""

from __future__ import annotations

import logging
import time
from typing import Literal

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse import csgraph
from tqdm.auto import tqdm

from mitld_lp.mdp import (
    MDP,
    absorbing_states,
    as_state_mask,
    backward_reachable,
    lift_policy,
    reduce,
)
from mitld_lp.solvers.lp import greedy_choices
from mitld_lp.solvers.result import IterationResult, Status

__all__ = ["interval_iteration", "evaluate_policy"]

logger = logging.getLogger(__name__)

_PROGRESS_MIN_STATES = 10_000
"""Below this many reduced states no progress bar is shown (the run is instant)."""


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a)
    a.setflags(write=False)
    return a


def interval_iteration(
    mdp: MDP,
    target: np.ndarray,
    *,
    tol: float = 1e-9,
    max_iterations: int = 1_000_000,
    progress: bool = True,
    gap: Literal["initial", "max"] = "initial",
) -> IterationResult:
    """Sound bounds ``lower <= Pmax(F target) <= upper`` on every state.

    Stops when the gap ``upper - lower`` is below ``tol`` at the initial state
    (``gap="initial"``, the default, as the design asks for) or at every state
    (``gap="max"``); the bounds are valid everywhere in either case, just not tight
    away from the initial state with ``"initial"``.  If the initial state is decided by
    the graph analysis (target or prob-0) no iteration is needed with ``"initial"``.
    Reaching ``max_iterations`` gives status ``MAX_ITERATIONS`` with the bracket so far.
    """
    start = time.perf_counter()
    q = reduce(mdp, target)
    n = q.n_states
    starts = np.asarray(q.row_groups[:-1], dtype=np.int64)
    bounds = np.zeros((n, 2))
    bounds[:, 1] = 1.0
    t2 = np.repeat(q.to_target[:, None], 2, axis=1)
    matrix = sp.csr_array(q.matrix)

    def current_gap() -> float:
        if n == 0:
            return 0.0
        if gap == "max":
            return float(np.max(bounds[:, 1] - bounds[:, 0]))
        if q.initial < 0:
            return 0.0
        return float(bounds[q.initial, 1] - bounds[q.initial, 0])

    iterations = 0
    width = current_gap()
    bar = tqdm(
        total=None, desc="interval iteration", unit="it", leave=False,
        disable=not progress or n < _PROGRESS_MIN_STATES,
    )
    try:
        while width >= tol and iterations < max_iterations:
            bounds = np.maximum.reduceat(matrix @ bounds + t2, starts, axis=0)
            iterations += 1
            width = current_gap()
            if iterations % 100 == 0:
                bar.update(100)
                bar.set_postfix(gap=f"{width:.3e}", refresh=False)
    finally:
        bar.close()

    status = Status.OPTIMAL if width < tol else Status.MAX_ITERATIONS
    np.clip(bounds, 0.0, 1.0, out=bounds)  # rounding can push the upper bound past 1
    lower = q.lift(bounds[:, 0])
    upper = q.lift(bounds[:, 1])
    policy = lift_policy(mdp, q, greedy_choices(q, bounds[:, 0]) if n else np.zeros(0, int))
    seconds = time.perf_counter() - start
    message = (
        f"gap ({gap}) {width:.3e} {'<' if status == Status.OPTIMAL else '>='} tol {tol:.1e} "
        f"after {iterations} iterations"
    )
    logger.info("interval iteration: %s, %.3fs", message, seconds)
    return IterationResult(
        status=status,
        lower=_frozen(lower),
        upper=_frozen(upper),
        value_lower=float(lower[mdp.initial]),
        value_upper=float(upper[mdp.initial]),
        iterations=iterations,
        seconds=seconds,
        policy=_frozen(policy),
        message=message,
    )


def evaluate_policy(
    mdp: MDP,
    target: np.ndarray,
    policy: np.ndarray,
    *,
    method: Literal["auto", "direct", "iterative"] = "auto",
) -> np.ndarray:
    r"""The exact probability of reaching ``target`` from every state under ``policy``.

    ``policy[s]`` is the choice row taken in ``s`` (one of ``mdp.choices(s)``), or ``-1``
    in a target state or an absorbing state (a single ``ABSORB`` self-loop), where the
    run stops.  On the induced Markov chain ``P_pi``: target states get 1; states that
    cannot reach the target in the chain's graph get 0 (this makes the rest transient);
    the rest solve the sparse linear system

    .. math:: (I - P_{\pi}[U, U])\, x = P_{\pi}[U, \mathit{target}]\, \mathbf 1.

    ``method="direct"`` factorises (sparse LU); ``"iterative"`` uses BiCGSTAB to a
    residual of 1e-12; ``"auto"`` factorises small systems and tries BiCGSTAB first on
    large ones, falling back to the factorisation if it does not converge.
    """
    target = as_state_mask(mdp, target, "target")
    policy = np.asarray(policy, dtype=np.int64)
    n = mdp.n_states
    if policy.shape != (n,):
        raise ValueError(f"policy: expected shape ({n},), got {policy.shape}")
    stop = policy < 0
    absorbing = absorbing_states(mdp)
    bad_stop = np.flatnonzero(stop & ~target & ~absorbing)
    if bad_stop.size:
        raise ValueError(
            f"policy: -1 (stop) in non-target, non-absorbing states {bad_stop[:10].tolist()}"
        )
    acting = ~stop & ~target
    lo, hi = mdp.row_groups[:-1], mdp.row_groups[1:]
    bad = np.flatnonzero(acting & ((policy < lo) | (policy >= hi)))
    if bad.size:
        raise ValueError(
            f"policy: choice not owned by its state in states {bad[:10].tolist()}"
        )
    states = np.flatnonzero(acting)
    chain = sp.csr_array(sp.csr_array(mdp.matrix)[policy[states]])  # rows: acting states
    coo = sp.coo_array(chain)
    keep = coo.data > 0
    src, dst = states[coo.row[keep]], np.asarray(coo.col[keep], dtype=np.int64)
    can = backward_reachable(n, src, dst, target)
    solve = acting & can
    values = np.where(target, 1.0, 0.0)
    if not solve.any():
        return values
    rows = np.flatnonzero(solve[states])  # positions in `chain` of the states to solve
    idx = np.flatnonzero(solve)
    sub = chain[rows]
    a = sp.eye_array(idx.size, format="csc") - sp.csc_array(sub[:, idx])
    b = np.asarray(sub @ target.astype(np.float64)).ravel()
    x = _solve_transient(a, b, method)
    values[idx] = np.clip(x, 0.0, 1.0)
    return values


_DIRECT_MAX = 5_000
"""``method="auto"`` always factorises systems up to this size."""

_DIRECT_FILL = 3e7
"""``method="auto"`` factorises larger systems when ``size * bandwidth`` after a reverse
Cuthill-McKee ordering (a cheap bound on the LU fill) is below this; otherwise (a random,
well-connected chain, whose LU fills in almost completely) BiCGSTAB goes first."""


def _banded_fill(a: sp.csc_array) -> float:
    pattern = sp.csr_matrix(abs(a) + abs(a.T))
    perm = csgraph.reverse_cuthill_mckee(pattern, symmetric_mode=True)
    pos = np.empty_like(perm)
    pos[perm] = np.arange(perm.size)
    coo = pattern.tocoo()
    width = int(np.max(np.abs(pos[coo.row] - pos[coo.col]), initial=0))
    return float(perm.size) * (width + 1)


def _solve_transient(
    a: sp.csc_array, b: np.ndarray, method: Literal["auto", "direct", "iterative"]
) -> np.ndarray:
    """Solve ``(I - Q) x = b`` for a transient sub-stochastic ``Q``."""
    size = b.shape[0]
    direct = method == "direct" or (
        method == "auto" and (size <= _DIRECT_MAX or _banded_fill(a) <= _DIRECT_FILL)
    )
    if direct:
        return np.asarray(spla.spsolve(a, b), dtype=np.float64).ravel()
    x, info = spla.bicgstab(sp.csr_array(a), b, rtol=1e-14, atol=1e-15, maxiter=5_000)
    x = np.asarray(x, dtype=np.float64).ravel()
    residual = float(np.max(np.abs(a @ x - b), initial=0.0))
    if info == 0 and residual <= 1e-12:
        return x
    logger.info("BiCGSTAB did not converge (info %d, residual %.1e)", info, residual)
    if method == "iterative":
        return x
    return np.asarray(spla.spsolve(a, b), dtype=np.float64).ravel()

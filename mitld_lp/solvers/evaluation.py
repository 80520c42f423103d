"""The exact probability of reaching a target under a deterministic policy: the sparse
linear system of its Markov chain, solved component by component (what every answer's
``lower`` is, and what the certificates check)."""

from __future__ import annotations

import logging
from typing import Literal

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDP, absorbing_states, as_state_mask
from mitld_lp.solvers.graph import backward_reachable
from mitld_lp.solvers.topological import solve_chain, transient_solve

__all__ = ["evaluate_policy"]

logger = logging.getLogger(__name__)


def evaluate_policy(
    mdp: MDP,
    target: np.ndarray,
    policy: np.ndarray,
    *,
    method: Literal["auto", "direct", "iterative"] = "auto",
    layers: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    r"""The exact probability of reaching ``target`` from every state under ``policy``.

    ``policy[s]`` is the choice row taken in ``s`` (one of ``mdp.choices(s)``), or ``-1``
    in a target state or an absorbing state (a single ``ABSORB`` self-loop), where the
    run stops.  On the induced Markov chain ``P_pi``: target states get 1; states that
    cannot reach the target in the chain's graph get 0 (this makes the rest transient);
    the rest solve the sparse linear system

    .. math:: (I - P_{\pi}[U, U])\, x = P_{\pi}[U, \mathit{target}]\, \mathbf 1.

    ``method="auto"`` solves the chain component by component in topological order
    (exact, single-threaded: an iterative solve slowed 88x on a loaded machine when BLAS
    threads fought); ``"direct"`` factorises the whole system (sparse LU);
    ``"iterative"`` uses BiCGSTAB to a residual of 1e-12.  ``layers``: the components and
    levels of the MDP's support graph (``Quotient.layers``, from the analysis), so that
    ``"auto"`` walks them instead of decomposing the chain again.
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
    chain = sp.csr_array(mdp.matrix)[policy[states]]  # rows: acting states
    counts = np.diff(chain.indptr)
    positive = chain.data > 0
    can = backward_reachable(n, np.repeat(states.astype(chain.indices.dtype), counts)[positive],
                             chain.indices[positive], target)
    del positive
    solve = acting & can
    values = np.where(target, 1.0, 0.0)
    if not solve.any():
        return values
    idx = np.flatnonzero(solve)
    rows = np.flatnonzero(solve[states])  # positions in `chain` of the states to solve
    b = (chain @ target.astype(np.float64))[rows]
    sub = _restricted(chain, rows, solve[states], idx, n)
    del chain  # the policy's rows are not needed while the system is solved
    x = _solve_transient(sub, b, method,
                         None if layers is None else (np.asarray(layers[0])[idx], layers[1]))
    values[idx] = np.clip(x, 0.0, 1.0)
    return values


def _restricted(chain: sp.csr_array, rows: np.ndarray, row_kept: np.ndarray,
                idx: np.ndarray, n: int) -> sp.csr_array:
    """``chain[rows][:, idx]`` as a square CSR matrix, made in one pass over ``chain``'s
    entries (SciPy's row and column indexing would copy the chain twice more)."""
    pos = np.full(n, -1, dtype=np.int64)
    pos[idx] = np.arange(idx.size)
    col = pos[chain.indices]
    del pos
    keep = (col >= 0) & np.repeat(row_kept, np.diff(chain.indptr))
    ends = np.concatenate([[0], np.cumsum(keep)])
    per_row = (ends[chain.indptr[1:]] - ends[chain.indptr[:-1]])[rows]
    indptr = np.concatenate([[0], np.cumsum(per_row)])
    return sp.csr_array((chain.data[keep], col[keep], indptr), shape=(idx.size, idx.size))


def _solve_transient(
    chain: sp.csr_array, b: np.ndarray, method: Literal["auto", "direct", "iterative"],
    layers: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Solve ``x = b + Q x`` for a transient sub-stochastic ``Q`` (``chain``): by
    components in topological order (``"auto"``,
    :func:`mitld_lp.solvers.topological.solve_chain`), one sparse LU of ``I - Q``
    (``"direct"``, :func:`mitld_lp.solvers.topological.transient_solve`) or BiCGSTAB
    to a residual of 1e-12 (``"iterative"``).  ``layers`` where a state's component has
    level -1 (outside the analysis's quotient, ``Quotient.layers``): not used, the chain
    is decomposed by itself."""
    if method == "auto":
        if layers is not None and (np.asarray(layers[1])[np.asarray(layers[0])] < 0).any():
            layers = None
        return solve_chain(chain, b, layers)
    if method == "direct":
        return transient_solve(chain, b)
    import scipy.sparse.linalg as spla

    a = sp.csc_array(sp.eye_array(b.shape[0], format="csc") - chain)
    x, info = spla.bicgstab(sp.csr_array(a), b, rtol=1e-14, atol=1e-15, maxiter=5_000)
    x = np.asarray(x, dtype=np.float64).ravel()
    residual = float(np.max(np.abs(a @ x - b), initial=0.0))
    if info != 0 or residual > 1e-12:
        logger.info("BiCGSTAB did not converge (info %d, residual %.1e)", info, residual)
    return x

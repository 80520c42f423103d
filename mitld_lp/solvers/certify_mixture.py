r"""Bounds in exact arithmetic on a randomised policy's values (the constrained route).

A constrained policy takes choice ``c`` of state ``s`` with probability ``pi(c)`` and
stays in ``s`` for ever with probability ``stay(s)`` (:mod:`mitld_lp.solvers.
constrained`).  The policy is the floats it stores, each state's normalised by their
exact sum ``S(s)``.  A quantity it is measured by (a probability: the verdict of the
absorbing state reached, or of staying; expected steps or costs: a reward per choice)
is the least solution of

.. math:: x(s) = \frac{1}{S(s)} \Big( \mathit{stay}(s)\, u(s) + \sum_c \pi(c)
          \big(w(c) + \textstyle\sum_j p(c, j)\, x(j)\big) \Big)

with ``x`` fixed on the absorbing states.  States from which the chain reaches neither
an absorbing state nor a stay (*trapped*: a closed class of the chain) are worth their
stay value for a probability (the run stays there for ever), and infinitely many steps
when undecided.  On the rest the chain is transient, so a vector checked to be a
sub-fixed point (rounded down) is a lower bound and a pre-fixed point (rounded up) an
upper bound, as for a deterministic policy (:mod:`mitld_lp.solvers.certify`): each
choice's expectation is bounded by :func:`~mitld_lp.solvers.rounding.below` /
:func:`~mitld_lp.solvers.rounding.above`, the mixture of ``k`` choices and the stay by
``gamma_{2k+6}`` more, and ``S(s)`` from its float sum.  The candidates are the float
values less / plus a slack ``W = (I - Q)^{-1} (delta x)``, retried larger.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.checks import Check
from mitld_lp.mdp import MDP
from mitld_lp.solvers.graph import backward_reachable
from mitld_lp.solvers.rounding import ETA, UNIT, above, below, rounding
from mitld_lp.solvers.rows import gather_ranges, row_entries

__all__ = ["Mixture", "mixture_bounds"]

RETRIES = 3
GROWTH = 16.0


@dataclass(frozen=True, slots=True)
class Mixture:
    """A quantity's bounds at the initial state under a randomised policy (``inf`` for
    steps that may never end), its float estimate ``value`` and the check of them."""

    lower: float
    upper: float
    value: float
    check: Check


def _gamma(n: np.ndarray) -> np.ndarray:
    return n * UNIT / (1.0 - n * UNIT)


def mixture_bounds(mdp: MDP, prob: np.ndarray, stay: np.ndarray, fixed: np.ndarray,
                   fixed_value: np.ndarray, reward: np.ndarray, stay_value: np.ndarray,
                   name: str, *, counts_steps: bool, undecided: np.ndarray,
                   eta: float = ETA) -> Mixture:
    """Bounds on the quantity (module docs) of the policy ``prob`` / ``stay`` on
    ``mdp``: ``fixed`` states (absorbing) worth ``fixed_value``; ``reward`` per choice
    (expected steps or cost, ``>= 0``; zero for a probability); ``stay_value`` per
    state; ``counts_steps``: a trapped ``undecided`` state is worth ``inf``.  The
    rewards are taken within ``eta`` (relative) of the model's, as probabilities are."""
    m = sp.csr_array(mdp.matrix)
    n = mdp.n_states
    cs = mdp.choice_state()
    prob = np.asarray(prob, dtype=np.float64)
    stay = np.asarray(stay, dtype=np.float64)
    fixed = np.asarray(fixed, dtype=bool)
    used = np.flatnonzero((prob > 0) & ~fixed[cs])
    # the chain's graph: s -> j when a used choice of s has j in its support
    lo, hi = m.indptr[used], m.indptr[used + 1]
    src = np.repeat(cs[used], hi - lo)
    dst = np.asarray(m.indices[gather_ranges(lo, hi)], dtype=np.int64)
    exits = fixed | (stay > 0)
    transient = ~fixed & backward_reachable(n, src, dst, exits)
    trapped = ~fixed & ~transient
    base_low = np.where(fixed, fixed_value, 0.0)
    base_high = base_low.copy()
    if counts_steps:
        base_high[trapped & undecided] = np.inf
    else:
        base_low[trapped] = stay_value[trapped]
        base_high[trapped] = stay_value[trapped]
    # states from which nothing worth anything is reached are worth exactly 0
    worth = (fixed & (np.asarray(fixed_value) > 0)) | ((stay > 0) & (stay_value > 0))
    worth[cs[used[reward[used] > 0]]] = True
    transient &= backward_reachable(n, src, dst, worth)
    if not counts_steps:  # and those from which nothing less than 1 is reached, exactly 1
        less = ((fixed | trapped) & (base_low < 1)) | ((stay > 0) & (stay_value < 1))
        less |= ~fixed & ~transient & ~trapped  # worth 0
        sure = transient & ~backward_reachable(n, src, dst, less)
        base_low[sure] = base_high[sure] = 1.0
        transient &= ~sure
    s0 = int(mdp.initial)
    if not transient[s0]:
        return Mixture(float(base_low[s0]), float(base_high[s0]), float(base_low[s0]),
                       Check(name, True, "decided by the chain's graph"))
    if np.isinf(base_high).any():
        # steps that never end once a trapped undecided state is reached; the states
        # that can reach one are unreachable from the initial state unless it is one
        bad = backward_reachable(n, src, dst, np.isinf(base_high))
        if bad[s0]:
            return Mixture(0.0, float("inf"), float("inf"), Check(
                name, True, "the policy may stay undecided for ever: infinitely many "
                "expected steps"))
        transient &= ~bad
        base_high[bad] = np.inf
    rnd = rounding(m, eta)
    idx = np.flatnonzero(transient)
    at = np.full(n, -1, dtype=np.int64)
    at[idx] = np.arange(idx.size)
    k = idx.size
    # the chain restricted to the transient states (floats: candidates only)
    weights = np.zeros(m.shape[0])
    weights[used] = prob[used]
    chain = sp.csr_array(sp.diags_array(weights) @ m)
    owner = sp.csr_array((np.ones(cs.size), (cs, np.arange(cs.size))), shape=(n, cs.size))
    q = sp.csr_array(owner @ chain)[idx]
    inner = sp.csr_array(q[:, idx])
    lu = _factor(sp.csc_array(sp.eye_array(k, format="csc") - inner))
    per_state_reward = owner @ (weights * reward) + stay * stay_value
    outside = np.where(transient, 0.0, 1.0)

    def solve(base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        b = per_state_reward[idx] + q @ (base * outside)
        x = lu.solve(b)
        residual = np.abs(x - (b + inner @ x))
        with np.errstate(divide="ignore", invalid="ignore"):
            delta = np.where(x > 0, 2.0 * (residual / x) + 64.0 * (eta + 64 * UNIT), 0.0)
        return x, np.maximum(lu.solve(delta * x), 0.0)

    x_low, w_low = solve(base_low)
    x_high, w_high = solve(base_high)
    cap = np.inf if counts_steps else 1.0
    sizes = np.bincount(cs[used], minlength=n)
    lower = upper = None
    for t in range(RETRIES + 1):
        scale = GROWTH**t
        if lower is None:
            cand = base_low.copy()
            cand[idx] = np.maximum(x_low - scale * w_low, 0.0)
            if _holds(m, rnd, cs, used, prob, stay, cand, reward, stay_value, idx, sizes,
                      eta, upper=False):
                lower = cand
        if upper is None:
            cand = base_high.copy()
            cand[idx] = np.minimum(x_high + scale * w_high, cap)
            if _holds(m, rnd, cs, used, prob, stay, cand, reward, stay_value, idx, sizes,
                      eta, upper=True):
                upper = cand
    ok = lower is not None and upper is not None
    low = 0.0 if lower is None else float(lower[s0])
    high = cap if upper is None else float(upper[s0])
    value = float(x_low[at[s0]])
    return Mixture(low, high, value, Check(name, ok, (
        f"[{low!r}, {high!r}]: sub- and pre-fixed points of the policy's chain checked in "
        f"exact arithmetic on {k} states" if ok else
        f"no candidate passed; the bounds are [{low!r}, {high!r}]")))


def _factor(a: sp.csc_array):  # noqa: ANN202 - SuperLU or a dense LU
    from mitld_lp.solvers.topological import chain_lu

    return chain_lu(a)


def _holds(m: sp.csr_array, rnd, cs: np.ndarray, used: np.ndarray,  # noqa: ANN001
           prob: np.ndarray, stay: np.ndarray, x: np.ndarray, reward: np.ndarray,
           stay_value: np.ndarray, idx: np.ndarray, sizes: np.ndarray, eta: float, *,
           upper: bool) -> bool:
    """Whether ``x`` is a pre- (``upper``) / sub-fixed point on the states ``idx``."""
    n = x.shape[0]
    sums = m[used] @ x
    exp = above(rnd, used, sums) if upper else below(rnd, used, sums)
    r = reward[used] * ((1.0 + eta) if upper else (1.0 - eta))
    mix = np.bincount(cs[used], weights=prob[used] * (r + exp), minlength=n) + stay * stay_value
    total = np.bincount(cs[used], weights=prob[used], minlength=n) + stay
    g = _gamma(2.0 * sizes + 6.0) * (1.0 + 2.0**-20)
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = (mix * (1.0 + 2.0 * g) / (total * (1.0 - g)) if upper else
                 mix * (1.0 - 2.0 * g) / (total * (1.0 + g)))
    ok = (x[idx] >= bound[idx]) if upper else (x[idx] <= bound[idx])
    if ok.all():
        return True
    # a convex combination: no arithmetic when the state's bound is beyond every value
    # its choices (with no reward) and its stay can lead to
    bad = idx[~ok]
    local, cols, _ = row_entries(m, used)
    owner = cs[used][local]
    ext = np.full(n, -np.inf if upper else np.inf)
    (np.maximum if upper else np.minimum).at(ext, owner, x[cols])
    paid = np.bincount(cs[used], weights=reward[used], minlength=n) > 0
    held = stay > 0
    ext[held] = (np.maximum if upper else np.minimum)(ext[held], stay_value[held])
    fine = ~paid[bad] & ((x[bad] >= ext[bad]) if upper else (x[bad] <= ext[bad]))
    return bool(fine.all())

"""The policy's side of a certificate (:mod:`mitld_lp.solvers.certify`): the checked
lower (``policy_lower``) or upper (``policy_upper``) bound of a deterministic policy's
value from its chain's values and slack, and :class:`Side`, what every bound of the
certificate hands back.  The module docs of :mod:`~mitld_lp.solvers.certify` say what
is checked and why it holds in exact arithmetic."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.checks import Check
from mitld_lp.mdp import MDP
from mitld_lp.solvers.certify_chain import Chain
from mitld_lp.solvers.result import read_only
from mitld_lp.solvers.rounding import Rounding, above, below
from mitld_lp.solvers.rows import row_columns, rows_dot
from mitld_lp.util.sparsetools import sparsetools

__all__ = ["GROWTH", "RETRIES", "Side", "policy_lower", "policy_upper", "scales"]

GROWTH = 16.0
"""How much the candidates' slack grows on each retry."""

RETRIES = 2
"""Retries with a larger slack before the repair and the fallbacks."""


@dataclass(frozen=True, slots=True, eq=False)
class Side:
    """One checked bound: its ``vector`` on every state and its ``value`` at the
    initial state (sound whatever ``check`` says: a failed check falls back to a
    trivial bound) and the ``check`` that says what was proved."""

    value: float
    check: Check
    vector: np.ndarray


def scales() -> list[float]:
    return [GROWTH**k for k in range(RETRIES + 1)]


def policy_lower(mdp: MDP, ch: Chain, rnd: Rounding) -> Side:
    """A lower bound on the policy's exact value at the initial state (module docs)."""
    return _policy_side(mdp, ch, rnd, upper=False)


def policy_upper(mdp: MDP, ch: Chain, rnd: Rounding) -> Side:
    """An upper bound on the policy's exact value at the initial state."""
    return _policy_side(mdp, ch, rnd, upper=True)


def _policy_side(mdp: MDP, ch: Chain, rnd: Rounding, *, upper: bool) -> Side:
    m = sp.csr_array(mdp.matrix)
    idx = np.flatnonzero(ch.solved)
    rows = ch.policy[idx]
    x = np.where(ch.sure, 1.0, 0.0)
    name = "upper bound: the policy's value" if upper else "lower bound: the policy's value"
    s0 = int(mdp.initial)
    if idx.size == 0:
        return Side(float(x[s0]), Check(name, True, "decided by the chain's graph: "
                                        f"{x[s0]:g} (no state left to solve)"), read_only(x))
    product = _RowsProduct(m, rows)  # the policy's rows gathered once, every slack
    for scale in scales():
        x[idx] = (np.minimum(ch.v + scale * ch.w, 1.0) if upper else
                  np.maximum(ch.v - scale * ch.w, 0.0))
        sums = product(x)
        ok = (x[idx] >= above(rnd, rows, sums)) if upper else (x[idx] <= below(rnd, rows, sums))
        if ok.all():
            return Side(float(x[s0]), Check(name, True, (
                f"{'pre' if upper else 'sub'}-fixed point of the policy's chain checked "
                f"in exact arithmetic on {idx.size} states (slack x{scale:g}, eta "
                f"{rnd.eta:.2g}): {float(x[s0])!r}")), read_only(x))
    worst = idx[~ok][:5].tolist()
    x[idx] = 1.0 if upper else 0.0
    return Side(float(x[s0]), Check(name, False, (
        f"the {'pre' if upper else 'sub'}-fixed point check failed in {int((~ok).sum())} "
        f"states (first {worst}) at every slack; the bound is the trivial "
        f"{x[s0]:g}")), read_only(x))


class _RowsProduct:
    """``m[rows] @ x`` for the policy's rows, the rows' entries gathered once for every
    slack (:func:`~mitld_lp.solvers.rows.row_columns`, SciPy's compiled row gather) and
    each product by SciPy's compiled CSR product on them: each row's sum from 0 in its
    entries' order, as :func:`~mitld_lp.solvers.rows.rows_dot` sums it (the same bits),
    without its index of every entry and its product array (QVBS csma 4-2's
    certificate peaked in it); :func:`~mitld_lp.solvers.rows.rows_dot` where SciPy's
    product does not take the arrays."""

    __slots__ = ("m", "rows", "cols", "vals", "ptr")

    def __init__(self, m: sp.csr_array, rows: np.ndarray) -> None:
        self.m, self.rows = m, rows
        self.cols = self.vals = self.ptr = None
        if (sparsetools is not None and m.data.dtype == np.float64
                and m.indices.dtype in (np.int32, np.int64)
                and m.indptr.dtype == m.indices.dtype and rows.size
                and int(rows.min()) >= 0):
            self.cols, self.vals = row_columns(m, rows)
            counts = m.indptr[rows + 1] - m.indptr[rows]
            if int(counts.sum()) < np.iinfo(self.cols.dtype).max:
                self.ptr = np.zeros(rows.size + 1, dtype=self.cols.dtype)
                np.cumsum(counts, out=self.ptr[1:])
            else:  # pragma: no cover - more entries than the columns' type counts
                self.cols = self.vals = None

    def __call__(self, x: np.ndarray) -> np.ndarray:
        if (self.ptr is None or x.dtype != np.float64 or x.ndim != 1
                or not x.flags.c_contiguous):
            return rows_dot(self.m, self.rows, x)
        sums = np.zeros(self.rows.size)
        sparsetools.csr_matvec(self.rows.size, x.shape[0], self.ptr, self.cols, self.vals, x, sums)
        return sums

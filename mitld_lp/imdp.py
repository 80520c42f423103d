"""An interval MDP on event outcomes: the product when some event's law is a band.

At a state the robot picks a choice (as in :class:`mitld_lp.mdp.MDP`); then nature picks,
for each *ambiguous* event pending in that choice, a hazard inside the event's band for
this step, ``h_i in [lo_i, hi_i]``; the events stay independent given those hazards.  The
step's successor distribution is then

    P_h(c) = sum_b  w_b(h) * B(c, b),    w_b(h) = prod_i h_i^{b_i} (1 - h_i)^{1 - b_i},

over the ``2^k`` *branches* ``b`` of the choice (bit ``i`` of ``b``: ambiguous event ``i``
happened), ``B(c, b)`` the successor distribution given that outcome (the events whose
law is exact, the world's move and the automaton already folded in).  A choice with no
ambiguous event has one branch, its ordinary row.

``E[V(next)] = sum_b w_b(h) (B(c, b) . V)`` is multilinear in ``h``, so its minimum over
the box of hazards is attained at a vertex: nature's choices can be taken among the ``2^k``
*vertex distributions* (each ``h_i`` at ``lo_i`` or ``hi_i``) without changing any value
(:func:`vertex_rows`).  A robust value is a max over choices of a min over these rows.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDP

__all__ = ["IntervalMDP", "VertexRows", "vertex_rows", "vertex_weights", "point_mdp"]


@dataclass(frozen=True, slots=True, eq=False)
class IntervalMDP:
    """The interval MDP (module docstring), laid out like :class:`~mitld_lp.mdp.MDP`.

    Attributes:
        branches: ``(n_branches, n_states)`` CSR; row ``b`` a successor distribution.
        branch_groups: ``(n_choices + 1,)``; the branches of choice ``c`` are rows
            ``branch_groups[c]:branch_groups[c+1]``, ``2^k`` of them for ``k`` ambiguous
            events, in the order of the bit masks ``0 .. 2^k - 1``.
        band_groups: ``(n_choices + 1,)``; choice ``c``'s ambiguous events' hazard
            intervals are ``band_lo[j], band_hi[j]`` for ``j`` in
            ``band_groups[c]:band_groups[c+1]`` (event ``i`` of the choice is bit ``i``).
        band_events: per entry of ``band_lo``, the event's name (for the DRN labels).
        row_groups, choice_actions, action_names, initial, target, sink, truncated,
        states: as in :class:`~mitld_lp.mdp.MDP`.
    """

    branches: sp.csr_array
    branch_groups: np.ndarray
    band_groups: np.ndarray
    band_lo: np.ndarray
    band_hi: np.ndarray
    band_events: tuple[str, ...]
    row_groups: np.ndarray
    choice_actions: np.ndarray
    action_names: tuple[str, ...]
    initial: int
    target: np.ndarray
    sink: np.ndarray
    truncated: np.ndarray
    states: Sequence[Hashable]

    @property
    def n_states(self) -> int:
        return int(self.row_groups.shape[0] - 1)

    @property
    def n_choices(self) -> int:
        return int(self.row_groups[-1])

    @property
    def n_branches(self) -> int:
        return int(self.branch_groups[-1])

    @property
    def n_transitions(self) -> int:
        return int(self.branches.nnz)

    @property
    def ambiguous_choices(self) -> int:
        """Choices with at least one ambiguous event."""
        return int(np.count_nonzero(np.diff(self.band_groups)))

    def choices(self, state: int) -> range:
        return range(int(self.row_groups[state]), int(self.row_groups[state + 1]))

    def choice_state(self) -> np.ndarray:
        return np.repeat(np.arange(self.n_states), np.diff(self.row_groups))

    def action_name(self, choice: int) -> str:
        a = int(self.choice_actions[choice])
        return "absorb" if a < 0 else self.action_names[a]


def vertex_weights(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``(m, 2^k, 2^k)``: for ``m`` choices with ``k`` hazard intervals each (``lo``,
    ``hi`` of shape ``(m, k)``), weight ``[c, v, b] = prod_i h_i^{b_i} (1-h_i)^{1-b_i}``
    with ``h_i = hi_i`` if bit ``i`` of vertex ``v`` is set, else ``lo_i``."""
    m, k = lo.shape
    n = 1 << k
    bits = (np.arange(n)[:, None] >> np.arange(k)[None, :]) & 1  # (n, k)
    h = np.where(bits[None, :, :] == 1, hi[:, None, :], lo[:, None, :])  # (m, v, k)
    w = np.ones((m, n, n))
    for i in range(k):
        hi_ = h[:, :, i][:, :, None]  # (m, v, 1)
        occurred = bits[:, i][None, None, :] == 1  # (1, 1, b)
        w *= np.where(occurred, hi_, 1.0 - hi_)
    return w


@dataclass(frozen=True, slots=True, eq=False)
class VertexRows:
    """Nature's vertex distributions: choice ``c``'s are rows
    ``groups[c]:groups[c+1]`` of ``matrix`` (one row for a choice with no ambiguity)."""

    matrix: sp.csr_array
    groups: np.ndarray


def vertex_rows(imdp: IntervalMDP) -> VertexRows:
    """Every choice's ``2^k`` vertex distributions ``sum_b w_b(h_v) B(c, b)`` (module
    docstring); entries of weight 0 (a hazard band reaching 0 or 1) are left out, so the
    rows' supports are the graph nature can make."""
    n_c = imdp.n_choices
    k = np.diff(imdp.band_groups).astype(np.int64)
    n_vert = np.left_shift(1, k)
    groups = np.zeros(n_c + 1, dtype=np.int64)
    np.cumsum(n_vert, out=groups[1:])
    rows, cols, vals = [], [], []
    for kk in np.unique(k).tolist():
        cs = np.flatnonzero(k == kk)
        n = 1 << kk
        if kk == 0:
            w = np.ones((cs.size, 1, 1))
        else:
            at = imdp.band_groups[cs][:, None] + np.arange(kk)[None, :]
            w = vertex_weights(imdp.band_lo[at], imdp.band_hi[at])
        v_row = groups[cs][:, None, None] + np.arange(n)[None, :, None]  # (m, v, 1)
        b_col = imdp.branch_groups[cs][:, None, None] + np.arange(n)[None, None, :]
        v_row, b_col = np.broadcast_arrays(v_row, b_col)
        rows.append(v_row.ravel())
        cols.append(b_col.ravel())
        vals.append(w.ravel())
    weights = sp.csr_array(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(int(groups[-1]), imdp.n_branches),
    )
    weights.eliminate_zeros()
    matrix = sp.csr_array(weights @ imdp.branches)
    matrix.eliminate_zeros()
    matrix.sort_indices()
    return VertexRows(matrix, groups)


def point_mdp(imdp: IntervalMDP, rows: sp.csr_array) -> MDP:
    """The MDP with the same states and choices whose row ``c`` is ``rows[c]`` (one
    distribution per choice: the interval MDP under one fixed choice of nature)."""
    return MDP(
        matrix=rows,
        row_groups=imdp.row_groups,
        choice_actions=imdp.choice_actions,
        action_names=imdp.action_names,
        initial=imdp.initial,
        target=imdp.target,
        sink=imdp.sink,
        truncated=imdp.truncated,
        states=imdp.states,
    )

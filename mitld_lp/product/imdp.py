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

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDP, ActionChoices

__all__ = ["BYTES_PER_WEIGHT", "IntervalMDP", "VertexRows", "WEIGHT_BLOCK", "middle_rows",
           "point_mdp", "vertex_rows", "vertex_weights"]


@dataclass(frozen=True, slots=True, eq=False, kw_only=True)
class IntervalMDP(ActionChoices):
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

    Its states, choices and actions are those of :class:`~mitld_lp.mdp.ActionChoices`.
    """

    branches: sp.csr_array
    branch_groups: np.ndarray
    band_groups: np.ndarray
    band_lo: np.ndarray
    band_hi: np.ndarray
    band_events: tuple[str, ...]

    @property
    def n_branches(self) -> int:
        return int(self.branch_groups[-1])

    @property
    def ambiguous_choices(self) -> int:
        """Choices with at least one ambiguous event."""
        return int(np.count_nonzero(np.diff(self.band_groups)))

    def distributions(self) -> tuple[sp.csr_array, np.ndarray | None]:
        """The branches, ``2^k`` rows per choice (its :class:`~mitld_lp.mdp.MDPShape`)."""
        return self.branches, self.branch_groups


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


WEIGHT_BLOCK = 1 << 21
"""Vertex weights (``2^k x 2^k`` per choice) computed together in :func:`vertex_rows`:
the block's dense weights and their sparse triplets stay within ~100 MB, however many
choices there are; a single choice wider than the block is computed alone."""

BYTES_PER_WEIGHT = 48
"""Peak bytes per vertex weight of one block in :func:`vertex_rows` (the dense weights,
the bit tables, the sparse triplets and the CSR conversion)."""


def vertex_rows(imdp: IntervalMDP) -> VertexRows:
    """Every choice's ``2^k`` vertex distributions ``sum_b w_b(h_v) B(c, b)`` (module
    docstring); entries of weight 0 (a hazard band reaching 0 or 1) are left out, so the
    rows' supports are the graph nature can make.  Computed a block of choices at a time
    (:data:`WEIGHT_BLOCK` weights), so that the transient weights stay bounded; the
    product's budget (:mod:`mitld_lp.product.budget`) counts the result and the widest
    block before the product is built."""
    n_c = imdp.n_choices
    k = np.diff(imdp.band_groups).astype(np.int64)
    n_vert = np.left_shift(1, k)
    groups = np.zeros(n_c + 1, dtype=np.int64)
    np.cumsum(n_vert, out=groups[1:])
    ids: list[np.ndarray] = []  # per block: the vertex rows it computed
    blocks: list[_Block | None] = []
    for kk in np.unique(k).tolist():
        cs = np.flatnonzero(k == kk)
        n = 1 << kk
        step = max(1, WEIGHT_BLOCK // (n * n))
        for start in range(0, cs.size, step):
            block = cs[start : start + step]
            ids.append((groups[block][:, None] + np.arange(n)[None, :]).ravel())
            blocks.append(_vertex_block(imdp, block, kk))
    return VertexRows(_in_order(blocks, ids, int(groups[-1]), imdp.n_states), groups)


def _in_order(blocks: list[_Block | None], ids: list[np.ndarray], n_rows: int,
              n_cols: int) -> sp.csr_array:
    """One CSR matrix whose row ``ids[i][j]`` is row ``j`` of ``blocks[i]``, filled in
    place (each block freed once copied): twice the result at the peak, not four
    times as stacking and then permuting would take."""
    lengths = np.zeros(n_rows, dtype=np.int64)
    for rows, block in zip(ids, blocks, strict=True):
        assert block is not None
        lengths[rows] = block.lengths
    indptr = np.zeros(n_rows + 1, dtype=np.int64)
    np.cumsum(lengths, out=indptr[1:])
    del lengths
    index = np.int32 if max(int(indptr[-1]), n_cols) < 2**31 else np.int64
    indices = np.empty(int(indptr[-1]), dtype=index)
    data = np.empty(int(indptr[-1]), dtype=np.float64)
    for i, rows in enumerate(ids):
        block = blocks[i]
        assert block is not None
        first = np.cumsum(block.lengths) - block.lengths  # each row's start in the block
        at = np.repeat(indptr[rows] - first, block.lengths) + np.arange(block.data.size)
        indices[at] = block.indices
        data[at] = block.data
        blocks[i] = None  # freed as soon as copied
    matrix = sp.csr_array((data, indices, indptr.astype(index)), shape=(n_rows, n_cols))
    matrix.sort_indices()
    return matrix


def _vertex_block(imdp: IntervalMDP, cs: np.ndarray, kk: int) -> _Block:
    """The vertex rows of the choices ``cs``, each with ``kk`` hazard intervals: ``2^kk``
    rows per choice, in the order of ``cs``."""
    n = 1 << kk
    m = cs.size
    if kk == 0:
        w = np.ones((m, 1, 1))
    else:
        at = imdp.band_groups[cs][:, None] + np.arange(kk)[None, :]
        w = vertex_weights(imdp.band_lo[at], imdp.band_hi[at])
    branch = (imdp.branch_groups[cs][:, None] + np.arange(n)[None, :]).ravel()
    rows = np.repeat(np.arange(m * n), n)
    cols = np.broadcast_to((np.arange(m) * n)[:, None, None] + np.arange(n)[None, None, :],
                           (m, n, n)).ravel()
    weights = sp.csr_array((w.ravel(), (rows, cols)), shape=(m * n, m * n))
    del w, rows, cols
    weights.eliminate_zeros()
    out = sp.csr_array(weights @ imdp.branches[branch])
    out.eliminate_zeros()
    return _Block(np.diff(out.indptr), out.indices.astype(np.int32, copy=False), out.data)


@dataclass(frozen=True, slots=True)
class _Block:
    """Rows of a block, compactly: their lengths, column indices, values."""

    lengths: np.ndarray
    indices: np.ndarray
    data: np.ndarray


def point_mdp(imdp: IntervalMDP, rows: sp.csr_array) -> MDP:
    """The MDP with the same states and choices whose row ``c`` is ``rows[c]`` (one
    distribution per choice: the interval MDP under one fixed choice of nature)."""
    return MDP(matrix=rows, **imdp.choice_fields())


def middle_rows(imdp: IntervalMDP) -> sp.csr_array:
    """Per choice, its distribution at the middle law: every ambiguous event's hazard at
    the middle of its interval, ``sum_b prod_i h_i^{b_i} (1 - h_i)^{1 - b_i} B(c, b)``."""
    k = np.diff(imdp.band_groups).astype(np.int64)
    rows, cols, vals = [], [], []
    for kk in np.unique(k).tolist():
        cs = np.flatnonzero(k == kk)
        n = 1 << kk
        w = np.ones((cs.size, n))
        if kk:
            at = imdp.band_groups[cs][:, None] + np.arange(kk)[None, :]
            mid = 0.5 * (imdp.band_lo[at] + imdp.band_hi[at])  # (m, k)
            bits = (np.arange(n)[:, None] >> np.arange(kk)[None, :]) & 1  # (n, k)
            for i in range(kk):
                w *= np.where(bits[None, :, i] == 1, mid[:, i:i + 1], 1.0 - mid[:, i:i + 1])
        rows.append(np.repeat(cs, n))
        cols.append((imdp.branch_groups[cs][:, None] + np.arange(n)[None, :]).ravel())
        vals.append(w.ravel())
    weights = sp.csr_array((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                           shape=(imdp.n_choices, imdp.n_branches))
    out = sp.csr_array(weights @ imdp.branches)
    out.eliminate_zeros()
    out.sort_indices()
    return out

"""A block of the quotient cut out of its rows (:class:`Block`, re-exported by
:mod:`mitld_lp.solvers.topological`, where the blocks are solved): its choices, the
moves inside it and the moves out of it.

:meth:`Block.of` cuts a block with NumPy, or, for a block of at least
:data:`CUT_KERNEL_MIN_STATES` states once the compiled kernels' load is paid and the
cut's kernel is cached (``mitld-lp warm``), in one compiled pass
(:mod:`mitld_lp.solvers.block_kernels`).  Both give the same block to the bit: the
same choices, each row's entries in their stored order with the same columns, the
same row pointers, index types and target probabilities.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.reduced import Quotient
from mitld_lp.solvers.rows import gather_ranges
from mitld_lp.util import kernel_loader

__all__ = ["Block", "CUT_KERNEL_MIN_STATES", "cut_compiled"]

CUT_KERNEL_MIN_STATES = 4096
"""The fewest states of a block :meth:`Block.of` cuts compiled (where its load is paid
and its machine code cached).  QVBS ``zeroconf`` 1000-4-false's block of 163,751
states (368,612 entries): 28 ms with NumPy, cut twice by the iteration and once by the
LP stage."""

_CUT_WARM: list[bool] = []  # whether the cut's kernel is cached, looked up once


def cut_compiled(n_states: int) -> bool:
    """Whether :meth:`Block.of` cuts a block of ``n_states`` states compiled: large
    enough, the compiled kernels' load paid in this process, and the kernel cached
    (never a compile, nor numba's import, in a solve)."""
    if n_states < CUT_KERNEL_MIN_STATES or not kernel_loader.compiled_paid():
        return False
    if not _CUT_WARM:
        from mitld_lp.solvers import block_kernels

        _CUT_WARM.append(kernel_loader.module_cached("mitld_lp.solvers.block_kernels",
                                                     block_kernels.KERNEL))
    return _CUT_WARM[0]


@dataclass(frozen=True, slots=True, eq=False)
class Block:
    """States ``states`` of the quotient (a union of components of one level) with
    their choices: ``inner`` moves inside the block (columns: positions in ``states``),
    ``outer`` the moves out of it (all quotient columns, the block's own entries left
    out), ``starts`` the first choice of each state."""

    states: np.ndarray
    choices: np.ndarray
    inner: sp.csr_array
    outer: sp.csr_array  # the rows' entries outside the block (each entry in one of the
    # two matrices: the rows are held once, not twice with the block's columns zeroed)
    starts: np.ndarray
    to_target: np.ndarray

    @property
    def groups(self) -> np.ndarray:
        """``(n_states + 1,)`` the row groups of the block's choices."""
        return np.append(self.starts, self.choices.shape[0])

    @staticmethod
    def of(q: Quotient, states: np.ndarray) -> Block:
        if cut_compiled(states.size):
            return _of_compiled(q, states)
        lo, hi = q.row_groups[states], q.row_groups[states + 1]
        choices = gather_ranges(lo, hi)
        rows = sp.csr_array(q.matrix[choices])
        index = rows.indices.dtype
        at = np.full(q.n_states, -1, dtype=index)  # a column's position in the block
        at[states] = np.arange(states.size, dtype=index)
        local = at[rows.indices]
        del at
        inside = local >= 0
        # the entries split in their rows' order: each row's sum adds the same terms
        inner = _entries(rows, inside, local, states.size)
        del local
        np.logical_not(inside, out=inside)
        outer = _entries(rows, inside, rows.indices, q.n_states)
        del rows, inside
        starts = np.concatenate([[0], np.cumsum(hi - lo)[:-1]]).astype(np.int64)
        return Block(states, choices, inner, outer, starts, q.to_target[choices])

    def exits(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """``(choices, 2)`` exit rewards from the lower / upper bounds downstream."""
        return np.column_stack([self.to_target + self.outer @ lo,
                                self.to_target + self.outer @ hi])


def _of_compiled(q: Quotient, states: np.ndarray) -> Block:
    """:meth:`Block.of` by the compiled cut (:mod:`mitld_lp.solvers.block_kernels`):
    its arrays made into the matrices as NumPy's route makes its own (SciPy's
    constructor given arrays of the same types)."""
    from mitld_lp.solvers.block_kernels import split_rows

    choices, starts, ip, ii, iv, op, oi, ov = split_rows(q.row_groups, q.matrix, states,
                                                         q.n_states)
    inner = sp.csr_array((iv, ii, ip), shape=(choices.size, states.size))
    outer = sp.csr_array((ov, oi, op), shape=(choices.size, q.n_states))
    return Block(states, choices, inner, outer, starts, q.to_target[choices])


def _entries(rows: sp.csr_array, keep: np.ndarray, columns: np.ndarray,
             n_columns: int) -> sp.csr_array:
    """The entries ``keep`` of ``rows`` (in their order), with the ``columns`` given."""
    before = np.concatenate([[0], np.cumsum(keep)])  # kept entries before each entry
    indptr = before[rows.indptr].astype(rows.indptr.dtype)
    del before
    return sp.csr_array((rows.data[keep], columns[keep], indptr),
                        shape=(rows.shape[0], n_columns))

"""The certificates' compiled checks (:mod:`mitld_lp.solvers.certify`,
:mod:`mitld_lp.solvers.certify_repair`): where a compiled kernel's load is paid in
the process already (:func:`~mitld_lp.util.kernel_loader.compiled_paid`) and the model
is large, the Bellman check's verdicts and the repair's needs by one call of a kernel
of :mod:`mitld_lp.solvers.certify_kernels`, the same floating-point operations on the
same operands as the NumPy code they replace (so the same verdicts and the same
values); None elsewhere, and the NumPy code runs.  This module imports no other module
of the certificates: ``st`` is :class:`~mitld_lp.solvers.certify_repair.Rows`
(its ``matrix``, ``groups``, ``nature`` and ``n_states`` read), which imports this."""

from __future__ import annotations

from typing import Any

import numpy as np

from mitld_lp.solvers.rounding import Rounding
from mitld_lp.util import kernel_loader

__all__ = ["COMPILED_CHECK_MIN_ROWS", "compiled_checks", "compiled_needs"]

COMPILED_CHECK_MIN_ROWS = 20_000
"""The fewest rows whose Bellman check (:func:`compiled_checks`) runs compiled, once a
compiled kernel's load is paid (the kernel's own first read, about 2 ms, against the
NumPy check's 10-20 ns a row and its dozen calls a batch)."""


def compiled_checks(st: Any, rnd: Rounding, x: np.ndarray, free: np.ndarray,
                    upper: bool, states: np.ndarray | None = None) -> np.ndarray | None:
    """Per row of the ``states``' choices (every state: the matrix's rows), whether it
    passes the Bellman check of :func:`~mitld_lp.solvers.certify._fails` (a ``free``
    state's rows pass), by one compiled pass
    (:func:`~mitld_lp.solvers.certify_kernels.bellman_rows`: the same verdicts); None
    where the NumPy check runs instead: fewer than :data:`COMPILED_CHECK_MIN_ROWS`
    rows, no compiled kernel loaded yet in this process, numba not installed, a value
    of ``x`` not finite, or arrays of other kinds than SciPy's product takes."""
    m = st.matrix
    if (m.shape[0] < COMPILED_CHECK_MIN_ROWS or not kernel_loader.compiled_paid()
            or x.dtype != np.float64 or x.ndim != 1 or m.data.dtype != np.float64
            or m.indices.dtype not in (np.int32, np.int64)
            or not bool(np.isfinite(x).all())):
        return None
    groups = np.asarray(st.groups, dtype=np.int64)
    nature = (np.zeros(0, dtype=np.int64) if st.nature is None else
              np.asarray(st.nature, dtype=np.int64))
    ends = groups[[0, -1]] if st.nature is None else nature[groups[[0, -1]]]
    if states is None and (int(ends[0]) != 0 or int(ends[1]) != m.shape[0]):
        return None  # (the rows are not the states' choices one after the other)
    try:
        from mitld_lp.solvers.certify_kernels import bellman_rows
    except ImportError:  # pragma: no cover - numba is a dependency of the solvers
        return None
    if states is None:
        states, n_rows = np.arange(st.n_states, dtype=np.int64), m.shape[0]
    else:
        states = np.asarray(states, dtype=np.int64)
        first = groups[states] if st.nature is None else nature[groups[states]]
        last = groups[states + 1] if st.nature is None else nature[groups[states + 1]]
        n_rows = int(np.sum(last - first))
    ok = np.empty(n_rows, dtype=bool)
    bellman_rows(states, groups, nature, m.indptr, m.indices, m.data,
                 np.ascontiguousarray(x), rnd.count, rnd.slack_of,
                 rnd.high_of if upper else rnd.low_of,
                 np.ascontiguousarray(free, dtype=bool), bool(upper), ok)
    return ok


def compiled_needs(st: Any, rnd: Rounding, x: np.ndarray, states: np.ndarray,
                    upper: bool) -> np.ndarray | None:
    """:func:`~mitld_lp.solvers.certify_repair._needed` by one compiled call
    (:func:`~mitld_lp.solvers.certify_kernels.state_needs`: the same operations on the
    same operands, so the same values), read from the matrix in place with no rows or
    entries gathered; None where :func:`compiled_checks` would not run, or where a
    state has no choice or a choice no row (NumPy's segmented reductions read the next
    segment's first value there)."""
    m = st.matrix
    if (m.shape[0] < COMPILED_CHECK_MIN_ROWS or not kernel_loader.compiled_paid()
            or x.dtype != np.float64 or x.ndim != 1 or m.data.dtype != np.float64
            or m.indices.dtype not in (np.int32, np.int64) or states.size == 0):
        return None
    states = np.asarray(states, dtype=np.int64)
    groups = np.asarray(st.groups, dtype=np.int64)
    if not bool(np.all(groups[states + 1] > groups[states])) or (
            st.nature is not None and not bool(np.all(np.diff(st.nature) > 0))):
        return None
    if not bool(np.isfinite(x).all()):
        return None
    try:
        from mitld_lp.solvers.certify_kernels import state_needs
    except ImportError:  # pragma: no cover - numba is a dependency of the solvers
        return None
    nature = (np.zeros(0, dtype=np.int64) if st.nature is None else
              np.asarray(st.nature, dtype=np.int64))
    out = np.empty(states.size)
    state_needs(states, groups, nature, m.indptr, m.indices, m.data,
                np.ascontiguousarray(x), rnd.count, rnd.slack_of,
                rnd.high_of if upper else rnd.low_of, bool(upper), out)
    return out

"""The numba kernel of the quotient's rows (:func:`~mitld_lp.solvers.quotient_rows.
quotient_rows`), run through :mod:`mitld_lp.util.kernel_loader` only where its cache
file is there and a compiled kernel's load is paid (the NumPy slices run elsewhere).

:func:`quotient_entries` reads each kept row's entries once, in stored order: an entry
into a kept state is written out (its column the reduced state), one into a removed
state adds ``value * factor`` to each of the row's sums, the factor 1 or 0 as its
state's class is in the sum's set or not, starting from 0.0, as SciPy's ``csr_matvec``
(``csr_matvecs``) adds ``value * x[column]`` in stored order into a zeroed result: an
entry into a kept state adds ``value * 0.0`` there, which leaves a sum of 0.0 or more
unchanged, so every sum is the same to the bit.  No slice temporaries: the quotient's
arrays and the sums are all it writes."""

from __future__ import annotations

from mitld_lp.util import kernel_loader

# numba's cached machine code run without importing numba; numba itself on a miss
numba = kernel_loader.lazy_numba(globals())

__all__ = ["quotient_entries"]


@numba.njit(cache=True, nogil=True)
def quotient_entries(indptr, indices, data, kept, column, n_red, factors, drop,
                     out_data, out_indices, out_indptr, sums):  # pragma: no cover
    """The kept rows ``kept`` of the matrix ``(data, indices, indptr)`` written as the
    quotient's (``column[state]``: the reduced state, or ``n_red +`` the removed state's
    class), entries into removed states dropped (``drop``) or written as a zero in
    column 0, and ``sums[r, j]`` the sum over row ``r``'s entries into removed states of
    ``value * factors[class, j]`` in stored order; returns the entries written."""
    at = 0
    k = factors.shape[1]
    out_indptr[0] = 0
    for r in range(kept.size):
        row = kept[r]
        for j in range(k):
            sums[r, j] = 0.0
        for e in range(indptr[row], indptr[row + 1]):
            c = column[indices[e]]
            d = data[e]
            if c >= n_red:
                cls = c - n_red
                for j in range(k):
                    sums[r, j] += d * factors[cls, j]
                if not drop:
                    out_data[at] = 0.0
                    out_indices[at] = 0
                    at += 1
            else:
                out_data[at] = d
                out_indices[at] = c
                at += 1
        out_indptr[r + 1] = at
    return at

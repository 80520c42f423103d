"""The numba kernels of a policy's chain factorised and solved in its strong components'
order (imported only through :mod:`mitld_lp.solvers.topo_chain`, where a kernel's load
is paid already and its cache is warm; compiled once, cached on disk).

A policy's chain ``x = b + Q x`` on a block of QVBS ``consensus`` has thousands of
components, nearly all single states, the largest some hundred states.  The states are
laid out component by component, downstream first (``order``; ``bounds`` the first
position of each component, ``at`` a state's position).  :func:`topo_factor`
factorises each component's ``I - Q`` restricted to it by sparse Gaussian elimination
row by row, without pivoting (``I - Q`` of a transient sub-stochastic ``Q`` is a
non-singular M-matrix, diagonally dominant by rows: every pivot is positive and the
elimination is stable), a row's fill found on a dense work row of the component's
size; the factors are kept sparse (the components are rings of the shared counter: a
122-state one fills to some 480 entries, where its dense square holds 14,884).
:func:`topo_solve` walks the components downstream first, each component's
right-hand side ``b + Q x`` over the states solved before it, then its two triangular
solves.  A single state is ``x = (b + sum Q x) / (1 - q)``.
"""

from __future__ import annotations

from mitld_lp.util import kernel_loader

# numba's cached machine code run without importing numba; numba itself on a miss
numba = kernel_loader.lazy_numba(globals())

__all__ = ["topo_factor", "topo_solve"]


@numba.njit(cache=True, nogil=True)
def topo_factor(order, bounds, at, indptr, indices, data, start, diag, fidx, fval,
                w, mark):  # pragma: no cover - compiled
    """The factors of each component's ``I - Q``: per position ``p`` its pivot
    ``diag[p]`` and its row of ``L`` (unit lower; multipliers) at ``fidx`` / ``fval``
    ``[start[3p], start[3p + 1])``, of ``U`` (above the pivot) at ``[start[3p + 1],
    start[3p + 2])``, both as positions; ``w`` / ``mark`` a zeroed work row and
    cleared marks of the largest component's size.  Returns -1 if every pivot is
    positive, the position of the first one that is not (the caller then factorises
    otherwise), -2 if an entry leaves to a component after its own (the order is
    not downstream first), or -3 if the factors fill more than ``fidx`` holds."""
    n_comp = bounds.shape[0] - 1
    room = fidx.shape[0]
    f = 0
    for c in range(n_comp):
        a = bounds[c]
        b = bounds[c + 1]
        for p in range(a, b):
            i = p - a
            lo = i
            hi = i
            mark[i] = True
            w[i] = 1.0
            row = order[p]
            for e in range(indptr[row], indptr[row + 1]):
                t = at[indices[e]]
                if t >= b:
                    return -2
                if t >= a:
                    j = t - a
                    if not mark[j]:
                        mark[j] = True
                        w[j] = 0.0
                        lo = min(lo, j)
                        hi = max(hi, j)
                    w[j] -= data[e]
            start[3 * p] = f
            for k in range(lo, i):
                if not mark[k]:
                    continue
                m = w[k]
                if m == 0.0:
                    mark[k] = False
                    continue
                m /= diag[a + k]
                if f >= room:
                    return -3
                fidx[f] = a + k
                fval[f] = m
                f += 1
                mark[k] = False
                for e in range(start[3 * (a + k) + 1], start[3 * (a + k) + 2]):
                    j = fidx[e] - a
                    if not mark[j]:
                        mark[j] = True
                        w[j] = 0.0
                        hi = max(hi, j)
                    w[j] -= m * fval[e]
            pivot = w[i]
            mark[i] = False
            if not pivot > 0.0:
                return p
            diag[p] = pivot
            start[3 * p + 1] = f
            for j in range(i + 1, hi + 1):
                if mark[j]:
                    mark[j] = False
                    if w[j] != 0.0:
                        if f >= room:
                            return -3
                        fidx[f] = a + j
                        fval[f] = w[j]
                        f += 1
            start[3 * p + 2] = f
    return -1


@numba.njit(cache=True, nogil=True)
def _solve_pair(order, bounds, at, indptr, indices, data, start, diag, fidx, fval,
                rhs, x, y):  # pragma: no cover - compiled
    """:func:`topo_solve` of two columns, each in a scalar (the same operations in the
    same order: the sums from 0, then the right-hand side, then the factors)."""
    n_comp = bounds.shape[0] - 1
    for c in range(n_comp):
        a = bounds[c]
        b = bounds[c + 1]
        for p in range(a, b):
            row = order[p]
            s0 = 0.0
            s1 = 0.0
            for e in range(indptr[row], indptr[row + 1]):
                col = indices[e]
                if at[col] < a:
                    v = data[e]
                    s0 += v * x[col, 0]
                    s1 += v * x[col, 1]
            s0 += rhs[row, 0]
            s1 += rhs[row, 1]
            for e in range(start[3 * p], start[3 * p + 1]):
                k = fidx[e]
                v = fval[e]
                s0 -= v * y[k, 0]
                s1 -= v * y[k, 1]
            y[p, 0] = s0
            y[p, 1] = s1
        for p in range(b - 1, a - 1, -1):
            s0 = y[p, 0]
            s1 = y[p, 1]
            for e in range(start[3 * p + 1], start[3 * p + 2]):
                k = fidx[e]
                v = fval[e]
                s0 -= v * y[k, 0]
                s1 -= v * y[k, 1]
            d = diag[p]
            s0 /= d
            s1 /= d
            y[p, 0] = s0
            y[p, 1] = s1
            row = order[p]
            x[row, 0] = s0
            x[row, 1] = s1


@numba.njit(cache=True, nogil=True)
def topo_solve(order, bounds, at, indptr, indices, data, start, diag, fidx, fval,
               rhs, x, y):  # pragma: no cover - compiled
    """``x = rhs + Q x`` (a column per right-hand side, rows in the chain's own state
    order) on :func:`topo_factor`'s factors, components downstream first; ``y`` a
    scratch ``(states, columns)`` array in position order."""
    n_comp = bounds.shape[0] - 1
    m = rhs.shape[1]
    if m == 2:  # a value and an exit time, the policy evaluations' pair
        _solve_pair(order, bounds, at, indptr, indices, data, start, diag, fidx, fval,
                    rhs, x, y)
        return
    for c in range(n_comp):
        a = bounds[c]
        b = bounds[c + 1]
        for p in range(a, b):
            row = order[p]
            for j in range(m):
                y[p, j] = 0.0
            for e in range(indptr[row], indptr[row + 1]):
                col = indices[e]
                if at[col] < a:
                    v = data[e]
                    for j in range(m):
                        y[p, j] += v * x[col, j]
            for j in range(m):
                y[p, j] += rhs[row, j]
            for e in range(start[3 * p], start[3 * p + 1]):  # L y = y (unit lower)
                k = fidx[e]
                v = fval[e]
                for j in range(m):
                    y[p, j] -= v * y[k, j]
        for p in range(b - 1, a - 1, -1):  # U z = y
            for e in range(start[3 * p + 1], start[3 * p + 2]):
                k = fidx[e]
                v = fval[e]
                for j in range(m):
                    y[p, j] -= v * y[k, j]
            d = diag[p]
            row = order[p]
            for j in range(m):
                y[p, j] /= d
                x[row, j] = y[p, j]

"""The numba kernels of :mod:`mitld_lp.solvers.eliminate` (imported only from there, and
only for a block large enough to pay numba's import; compiled once, cached on disk).

The eliminated states ``S`` are walked component by component of their own graph
(``comp_ptr`` / ``comp_states``: each component's ``S``-local states, downstream first).
A single state is solved by its self-loop, a cyclic component densely (LAPACK's LU
through ``np.linalg.solve``; :mod:`.eliminate` keeps larger components in the LP).  In
``s_idx`` an entry ``t >= 0`` is an ``S``-local successor, ``t < 0`` the ``M``-local
state ``-1 - t``.
"""

from __future__ import annotations

import numba
import numpy as np

from mitld_lp.util import numba_cache, numba_narrow

numba_narrow.install()  # cached kernels loaded without numba's whole target registry
numba_cache.install()  # processes compiling at once share the disk cache safely

__all__ = ["boundary_rows", "downstream", "lu_solve", "reach", "reduced_rows", "upstream"]


@numba.njit(cache=True, nogil=True)
def _grow(idx, val, used, more):  # pragma: no cover - compiled
    cap = idx.shape[0]
    if used + more <= cap:
        return idx, val
    while used + more > cap:
        cap *= 2
    new_idx = np.empty(cap, np.int64)
    new_val = np.empty(cap)
    new_idx[:used] = idx[:used]
    new_val[:used] = val[:used]
    return new_idx, new_val


@numba.njit(cache=True, nogil=True)
def boundary_rows(comp_ptr, comp_states, needed, port, s_ptr, s_idx, s_val, s_rew, n_m,
                  max_fill, max_work):  # pragma: no cover - compiled
    """``a = (I - P_SS)^-1 r_S`` and the rows of ``B = (I - P_SS)^-1 P_SM`` (sparse over
    ``M``) of the ``port`` states of the ``needed`` components, downstream first (a
    cyclic component's port rows as ``E_P' (I - P_CC)^-1`` times its right-hand sides:
    its other states' rows are never formed).  Returns ``a`` (on the ports), each row's
    start and length in the buffers, the buffers, the work done (the entries read and
    the dense solves' floating-point operations) and whether it is complete: it stops
    once the rows hold more than ``max_fill`` entries, or before the work would
    pass ``max_work`` (the caller solves the whole LP instead)."""
    n_s = s_rew.shape[0]
    a = np.zeros(n_s)
    row_ptr = np.zeros(n_s, np.int64)
    row_len = np.zeros(n_s, np.int64)
    b_idx = np.empty(1 << 12, np.int64)
    b_val = np.empty(1 << 12)
    used = 0
    col_pos = np.full(n_m, -1, np.int64)
    touched = np.empty(n_m, np.int64)
    pos = np.full(n_s, -1, np.int64)
    work = 0.0
    for c in range(comp_ptr.shape[0] - 1):
        if not needed[c]:
            continue
        lo, hi = comp_ptr[c], comp_ptr[c + 1]
        k = hi - lo
        for i in range(k):
            pos[comp_states[lo + i]] = i
        # the M columns the component's rows reach (directly or through S below)
        nt = 0
        for i in range(k):
            s = comp_states[lo + i]
            for e in range(s_ptr[s], s_ptr[s + 1]):
                t = s_idx[e]
                if t < 0:
                    j = -1 - t
                    if col_pos[j] < 0:
                        col_pos[j] = nt
                        touched[nt] = j
                        nt += 1
                elif pos[t] < 0:
                    work += 2.0 * row_len[t]  # read here and in the right-hand side
                    for f in range(row_ptr[t], row_ptr[t] + row_len[t]):
                        j = b_idx[f]
                        if col_pos[j] < 0:
                            col_pos[j] = nt
                            touched[nt] = j
                            nt += 1
        n_p = 0
        for i in range(k):
            if port[comp_states[lo + i]]:
                n_p += 1
        if k > 1:  # LU, the port rows of the inverse, their products with rhs
            work += k * k * (k / 3.0 + n_p) + 2.0 * n_p * k * (nt + 1)
        if work > max_work:
            return a, row_ptr, row_len, b_idx[:used], b_val[:used], work, False
        mat = np.zeros((k, k))
        rhs = np.zeros((k, nt + 1))  # the last column: the reward
        for i in range(k):
            s = comp_states[lo + i]
            mat[i, i] = 1.0
            rhs[i, nt] = s_rew[s]
            for e in range(s_ptr[s], s_ptr[s + 1]):
                t = s_idx[e]
                w = s_val[e]
                if t < 0:
                    rhs[i, col_pos[-1 - t]] += w
                elif pos[t] >= 0:
                    mat[i, pos[t]] -= w
                else:
                    rhs[i, nt] += w * a[t]
                    for f in range(row_ptr[t], row_ptr[t] + row_len[t]):
                        rhs[i, col_pos[b_idx[f]]] += w * b_val[f]
        if k == 1:  # a needed single state is a port
            sol = rhs / mat[0, 0]
        else:  # the port rows of the inverse, then their products with rhs
            unit = np.zeros((k, n_p))
            r = 0
            for i in range(k):
                if port[comp_states[lo + i]]:
                    unit[i, r] = 1.0
                    r += 1
            sol = np.linalg.solve(np.ascontiguousarray(mat.T), unit).T @ rhs
        b_idx, b_val = _grow(b_idx, b_val, np.int64(used), np.int64(n_p * nt))  # one signature
        r = 0
        for i in range(k):
            s = comp_states[lo + i]
            pos[s] = -1
            if not port[s]:
                continue
            a[s] = sol[r, nt]
            row_ptr[s] = used
            for q in range(nt):
                if sol[r, q] != 0.0:
                    b_idx[used] = touched[q]
                    b_val[used] = sol[r, q]
                    used += 1
            row_len[s] = used - row_ptr[s]
            r += 1
        for q in range(nt):
            col_pos[touched[q]] = -1
        if used > max_fill:
            return a, row_ptr, row_len, b_idx[:used], b_val[:used], work, False
    return a, row_ptr, row_len, b_idx[:used], b_val[:used], work, True


@numba.njit(cache=True, nogil=True)
def reduced_rows(c_ptr, c_idx, c_val, c_rew, a, row_ptr, row_len, b_idx, b_val,
                 n_m):  # pragma: no cover - compiled
    """The rows ``P(c, M) + P(c, S) B`` (CSR over ``M``) and rewards ``r(c) + P(c, S) a``
    of the choices of ``M`` (``c_*``: their rows, coded as ``s_idx``)."""
    n_c = c_ptr.shape[0] - 1
    out_ptr = np.zeros(n_c + 1, np.int64)
    o_idx = np.empty(max(16, 2 * c_idx.shape[0]), np.int64)
    o_val = np.empty(o_idx.shape[0])
    rew = np.empty(n_c)
    spa = np.zeros(n_m)
    mark = np.full(n_m, False)
    touched = np.empty(n_m, np.int64)
    used = 0
    for c in range(n_c):
        acc = c_rew[c]
        nt = 0
        for e in range(c_ptr[c], c_ptr[c + 1]):
            t = c_idx[e]
            w = c_val[e]
            if t < 0:
                j = -1 - t
                if not mark[j]:
                    mark[j] = True
                    touched[nt] = j
                    nt += 1
                spa[j] += w
            else:
                acc += w * a[t]
                for f in range(row_ptr[t], row_ptr[t] + row_len[t]):
                    j = b_idx[f]
                    if not mark[j]:
                        mark[j] = True
                        touched[nt] = j
                        nt += 1
                    spa[j] += w * b_val[f]
        rew[c] = acc
        o_idx, o_val = _grow(o_idx, o_val, np.int64(used), np.int64(nt))  # one signature
        for i in range(nt):
            j = touched[i]
            o_idx[used] = j
            o_val[used] = spa[j]
            used += 1
            spa[j] = 0.0
            mark[j] = False
        out_ptr[c + 1] = used
    return out_ptr, o_idx[:used], o_val[:used], rew


@numba.njit(cache=True, nogil=True)
def downstream(comp_ptr, comp_states, s_ptr, s_idx, s_val, base):  # pragma: no cover
    """``x = (I - P_SS)^-1 base``, components downstream first (``M`` entries of the
    rows are skipped: their part is in ``base``)."""
    n_s = base.shape[0]
    x = np.zeros(n_s)
    pos = np.full(n_s, -1, np.int64)
    for c in range(comp_ptr.shape[0] - 1):
        lo, hi = comp_ptr[c], comp_ptr[c + 1]
        k = hi - lo
        for i in range(k):
            pos[comp_states[lo + i]] = i
        mat = np.zeros((k, k))
        rhs = np.zeros(k)
        for i in range(k):
            s = comp_states[lo + i]
            mat[i, i] = 1.0
            rhs[i] = base[s]
            for e in range(s_ptr[s], s_ptr[s + 1]):
                t = s_idx[e]
                if t < 0:
                    continue
                if pos[t] >= 0:
                    mat[i, pos[t]] -= s_val[e]
                else:
                    rhs[i] += s_val[e] * x[t]
        sol = rhs / mat[0, 0] if k == 1 else np.linalg.solve(mat, rhs)
        for i in range(k):
            s = comp_states[lo + i]
            x[s] = sol[i]
            pos[s] = -1
    return x


@numba.njit(cache=True, nogil=True)
def upstream(comp_ptr, comp_states, s_ptr, s_idx, s_val, base):  # pragma: no cover
    """``x = (I - P_SS)^-T base`` (the flow through ``S`` from the start weights
    ``base``), components upstream first: a component's inflow is complete once every
    component upstream of it has pushed its flow."""
    n_s = base.shape[0]
    x = np.zeros(n_s)
    inflow = base.copy()
    pos = np.full(n_s, -1, np.int64)
    for c in range(comp_ptr.shape[0] - 2, -1, -1):
        lo, hi = comp_ptr[c], comp_ptr[c + 1]
        k = hi - lo
        for i in range(k):
            pos[comp_states[lo + i]] = i
        mat = np.zeros((k, k))  # (I - P_CC)^T
        rhs = np.zeros(k)
        for i in range(k):
            s = comp_states[lo + i]
            mat[i, i] += 1.0
            rhs[i] = inflow[s]
            for e in range(s_ptr[s], s_ptr[s + 1]):
                t = s_idx[e]
                if t >= 0 and pos[t] >= 0:
                    mat[pos[t], i] -= s_val[e]
        sol = rhs / mat[0, 0] if k == 1 else np.linalg.solve(mat, rhs)
        for i in range(k):
            s = comp_states[lo + i]
            x[s] = sol[i]
        for i in range(k):
            s = comp_states[lo + i]
            for e in range(s_ptr[s], s_ptr[s + 1]):
                t = s_idx[e]
                if t >= 0 and pos[t] < 0:
                    inflow[t] += s_val[e] * x[s]
        for i in range(k):
            pos[comp_states[lo + i]] = -1
    return x


@numba.njit(cache=True, nogil=True)
def reach(comp_ptr, comp_states, comp_of, s_ptr, s_idx, seed):  # pragma: no cover
    """Per component (downstream first in ``comp_ptr``), whether it holds a ``seed``
    state or lies downstream of one, and per state whether it is a *port*: a seed, or
    entered from another reached component (only a port's row of ``B`` is ever read).
    Walked upstream first, each reached component marks the states its rows enter."""
    n_c = comp_ptr.shape[0] - 1
    hit = np.zeros(n_c, np.bool_)
    port = seed.copy()
    for c in range(n_c - 1, -1, -1):
        for i in range(comp_ptr[c], comp_ptr[c + 1]):
            if port[comp_states[i]]:
                hit[c] = True
        if not hit[c]:
            continue
        for i in range(comp_ptr[c], comp_ptr[c + 1]):
            s = comp_states[i]
            for e in range(s_ptr[s], s_ptr[s + 1]):
                t = s_idx[e]
                if t >= 0 and comp_of[t] != c:
                    port[t] = True
    return hit, port


@numba.njit(cache=True, nogil=True)
def lu_solve(l_ptr, l_idx, l_val, u_ptr, u_idx, u_val, x):  # pragma: no cover - compiled
    """``x <- U^-1 L^-1 x`` in place for the CSC factors ``L`` (lower) and ``U`` (upper)
    of a sparse LU (:mod:`.sparse_elimination`: SuperLU's, permutations applied by the
    caller) and a C-ordered block of right-hand sides ``x`` (one row a state): every
    entry of a factor is one pass over a row of ``x``, where SuperLU's own solve takes
    the right-hand sides one at a time."""
    n, k = x.shape
    for j in range(n):  # forward, column by column
        d = 0.0
        for e in range(l_ptr[j], l_ptr[j + 1]):
            if l_idx[e] == j:
                d = l_val[e]
        if d != 1.0:
            for c in range(k):
                x[j, c] /= d
        for e in range(l_ptr[j], l_ptr[j + 1]):
            i = l_idx[e]
            if i > j:
                w = l_val[e]
                for c in range(k):
                    x[i, c] -= w * x[j, c]
    for j in range(n - 1, -1, -1):  # backward
        d = 0.0
        for e in range(u_ptr[j], u_ptr[j + 1]):
            if u_idx[e] == j:
                d = u_val[e]
        for c in range(k):
            x[j, c] /= d
        for e in range(u_ptr[j], u_ptr[j + 1]):
            i = u_idx[e]
            if i < j:
                w = u_val[e]
                for c in range(k):
                    x[i, c] -= w * x[j, c]

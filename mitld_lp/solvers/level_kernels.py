"""The numba kernels of the single-state level walks (imported only through
:func:`mitld_lp.solvers.topological.level_kernels`, and only for a product of many
levels large enough to pay numba's import; compiled once, cached on disk).

Each kernel walks a run of levels' single-state components in the order the NumPy
walk takes them and does the same floating-point operations in the same order (a
choice's successor terms summed from 0 in its entries' order, then added to its
reward; a flow added to a successor in the order of the entries that carry it), so
its answers are the NumPy walk's to the last bit: one call for a run of levels in
place of a dozen NumPy calls per level (a deadline clock makes a thousand levels and
more).  The arrays are those of :class:`~mitld_lp.solvers.topological.SingleLevels`
(states in level order, their choices) and the quotient's own CSR arrays (a choice's
row read in place, the state's self-loop skipped: the same terms in the same order as
the copied rows without it, which the NumPy walks read; no copy of the rows), or
a chain's CSR arrays and :class:`~mitld_lp.solvers.graph.Blocks` order.  One
exception: :func:`chain_flow` pushes a level's single states before its cyclic ones,
where :meth:`~mitld_lp.solvers.chain_levels.ChainLevels.solve_transposed`'s NumPy walk
pushes them in level order, so a successor of both may differ in its last bits.
"""

from __future__ import annotations

import numpy as np

from mitld_lp.util import kernel_loader

# numba's cached machine code run without importing numba; numba itself on a miss
# (without PyYAML, the narrow load, the disk cache's lock: kernel_loader.numba_module)
numba = kernel_loader.lazy_numba(globals())


__all__ = ["chain_flow", "chain_solve", "chain_values", "single_bounds",
           "single_bounds_values", "single_flow", "single_values"]


@numba.njit(cache=True, nogil=True)
def _score(acc, reward, leave):  # pragma: no cover - compiled
    """``clip((reward + acc) / leave, 0, 1)``, 0 where nothing leaves."""
    val = (reward + acc) / leave if leave > 0.0 else 0.0
    return min(max(val, 0.0), 1.0)


@numba.njit(cache=True, nogil=True)
def _row_sums(indptr, indices, data, ch, s, x, acc):  # pragma: no cover - compiled
    """``acc[j] = sum P(ch, t) x[t, j]`` over row ``ch``'s entries but those in column
    ``s`` (the state's self-loop), each sum from 0 in the entries' order."""
    k = acc.shape[0]
    for j in range(k):
        acc[j] = 0.0
    for e in range(indptr[ch], indptr[ch + 1]):
        t = indices[e]
        if t == s:
            continue
        w = data[e]
        for j in range(k):
            acc[j] += w * x[t, j]


@numba.njit(cache=True, nogil=True)
def single_bounds(a, z, state_choice, indptr, states, choices, indices, data, leave,
                  rewards, bounds, minimise):  # pragma: no cover - compiled
    """:meth:`SingleLevels.solve` on the single states ``a`` to ``z - 1`` (their level
    order): every column of ``bounds`` at once, each state the best over its choices of
    ``clip((rewards + sum P x) / (1 - p), 0, 1)`` (the sum over the choice's row of the
    quotient's CSR arrays, its self-loop skipped)."""
    k = bounds.shape[1]
    acc = np.empty(k)
    best = np.empty(k)
    for i in range(a, z):
        s = states[i]
        for c in range(state_choice[i], state_choice[i + 1]):
            ch = choices[c]
            _row_sums(indptr, indices, data, ch, s, bounds, acc)
            lv = leave[c]
            for j in range(k):
                val = _score(acc[j], rewards[ch, j], lv)
                if c == state_choice[i]:
                    best[j] = val
                elif minimise:
                    best[j] = min(best[j], val)
                else:
                    best[j] = max(best[j], val)
        for j in range(k):
            bounds[s, j] = best[j]


@numba.njit(cache=True, nogil=True)
def single_bounds_values(a, z, state_choice, indptr, states, choices, indices, data,
                         leave, rewards, bounds, minimise, picked, skip, tie, values,
                         picks):  # pragma: no cover - compiled
    """:func:`single_bounds` (the same bounds to the bit) and, in the same pass, for each
    column ``picked[h]`` of ``rewards``, :func:`single_values` on its own values
    ``values[h]`` (a state ``skip[h, s]`` left out, at the 0 it holds): each
    state's choices scored on the values below it, ties within ``tie`` of the best to
    the larger one-step reward (the least for a minimum), then the first; the pick's
    score written, the pick (a quotient choice) in ``picks[h, i - a]`` (-1 where
    skipped).  The same sums in the same order as :func:`single_values`, so the same
    values and choices to the bit."""
    k = bounds.shape[1]
    p = picked.shape[0]
    width = 1
    for i in range(a, z):
        width = max(width, state_choice[i + 1] - state_choice[i])
    acc = np.empty(k)
    best = np.empty(k)
    score = np.empty(width)
    for i in range(a, z):
        s = states[i]
        c0 = state_choice[i]
        n = state_choice[i + 1] - c0
        for m in range(n):
            c = c0 + m
            ch = choices[c]
            _row_sums(indptr, indices, data, ch, s, bounds, acc)
            lv = leave[c]
            for j in range(k):
                val = _score(acc[j], rewards[ch, j], lv)
                if m == 0:
                    best[j] = val
                elif minimise:
                    best[j] = min(best[j], val)
                else:
                    best[j] = max(best[j], val)
        for j in range(k):
            bounds[s, j] = best[j]
        for h in range(p):
            picks[h, i - a] = -1
            if skip[h, s]:
                continue
            col = picked[h]
            for m in range(n):
                c = c0 + m
                ch = choices[c]
                total = 0.0
                for e in range(indptr[ch], indptr[ch + 1]):
                    t = indices[e]
                    if t != s:
                        total += data[e] * values[h, t]
                score[m] = _score(total, rewards[ch, col], leave[c])
            top_score = score[0]
            for m in range(1, n):
                top_score = min(top_score, score[m]) if minimise else max(top_score,
                                                                          score[m])
            slack = -tie * abs(top_score)
            top = -np.inf
            for m in range(n):
                gain = top_score - score[m] if minimise else score[m] - top_score
                if gain >= slack:
                    key = rewards[choices[c0 + m], col]
                    top = max(top, -key if minimise else key)
            pick = -1
            for m in range(n):
                gain = top_score - score[m] if minimise else score[m] - top_score
                if gain >= slack:
                    key = rewards[choices[c0 + m], col]
                    if (-key if minimise else key) >= top:
                        pick = m
                        break
            values[h, s] = score[pick]
            picks[h, i - a] = choices[c0 + pick]


@numba.njit(cache=True, nogil=True)
def single_values(a, z, state_choice, indptr, states, choices, indices, data, leave,
                  to_target, skip, values, reduced_choice, weights, tie,
                  minimise):  # pragma: no cover - compiled
    """:func:`~mitld_lp.solvers.topological.solve_single_states` on the single states
    ``a`` to ``z - 1`` but the ``skip`` ones: each state's value, its choice (ties
    within ``tie`` of the best relative to it go to the choice of the largest one-step
    target probability for a maximum, the least for a minimum, then the first:
    :func:`~mitld_lp.solvers.graph.segmented_argmax`'s rule) and that choice's
    weight 1."""
    width = 1
    for i in range(a, z):
        width = max(width, state_choice[i + 1] - state_choice[i])
    score = np.empty(width)
    for i in range(a, z):
        s = states[i]
        if skip[s]:
            continue
        c0 = state_choice[i]
        n = state_choice[i + 1] - c0
        for m in range(n):
            c = c0 + m
            ch = choices[c]
            acc = 0.0
            for e in range(indptr[ch], indptr[ch + 1]):
                t = indices[e]
                if t != s:
                    acc += data[e] * values[t]
            score[m] = _score(acc, to_target[ch], leave[c])
        best = score[0]
        for m in range(1, n):
            best = min(best, score[m]) if minimise else max(best, score[m])
        slack = -tie * abs(best)
        top = -np.inf
        for m in range(n):
            gain = best - score[m] if minimise else score[m] - best
            if gain >= slack:
                key = to_target[choices[c0 + m]]
                top = max(top, -key if minimise else key)
        pick = -1
        for m in range(n):
            gain = best - score[m] if minimise else score[m] - best
            if gain >= slack:
                key = to_target[choices[c0 + m]]
                if (-key if minimise else key) >= top:
                    pick = m
                    break
        ch = choices[c0 + pick]
        values[s] = score[pick]
        reduced_choice[s] = ch
        weights[ch] = 1.0


@numba.njit(cache=True, nogil=True)
def single_flow(first, stop, level_state, state_choice, indptr, states, choices,
                indices, data, self_loop, weights, x):  # pragma: no cover - compiled
    """:func:`~mitld_lp.solvers.lp_blocks.policy_flow` on the single states of levels
    ``stop - 1`` down to ``first`` (upstream first): each state's inflow divided by
    what its choices do not keep, then pushed along its choices' entries (their rows
    of the quotient's CSR arrays, the self-loops skipped) in their order."""
    for level in range(stop - 1, first - 1, -1):
        for i in range(level_state[level], level_state[level + 1]):
            s = states[i]
            stay = 0.0
            for c in range(state_choice[i], state_choice[i + 1]):
                ch = choices[c]
                stay += weights[ch] * self_loop[ch]
            x[s] /= 1.0 - stay
            for c in range(state_choice[i], state_choice[i + 1]):
                ch = choices[c]
                y = weights[ch] * x[s]
                for e in range(indptr[ch], indptr[ch + 1]):
                    t = indices[e]
                    if t != s:
                        x[t] += data[e] * y


@numba.njit(cache=True, nogil=True)
def chain_values(order, indptr, indices, data, diag, b, kappa, v,
                 w):  # pragma: no cover - compiled
    """The single states ``order`` (downstream first) of a transient chain (CSR arrays;
    a state's own entry reads its ``v`` and ``w`` still 0): each one's value
    ``v = (b + sum Q v) / (1 - q)`` and slack ``w = (2 kappa v + sum Q w) / (1 - q)``
    (:func:`mitld_lp.solvers.certify_chain.chain`)."""
    for i in range(order.shape[0]):
        s = order[i]
        dv = 0.0
        dw = 0.0
        for e in range(indptr[s], indptr[s + 1]):
            t = indices[e]
            dv += data[e] * v[t]
            dw += data[e] * w[t]
        v[s] = (b[s] + dv) / (1.0 - diag[s])
        w[s] = (2.0 * kappa[s] * v[s] + dw) / (1.0 - diag[s])


@numba.njit(cache=True, nogil=True)
def chain_solve(order, indptr, indices, data, diag, rhs, x):  # pragma: no cover - compiled
    """The single states ``order`` (downstream first) of a transient chain ``x = rhs +
    Q x`` (CSR arrays; a column of ``rhs`` and ``x`` per right-hand side; a state's own
    entry reads its ``x`` still 0): ``x = (rhs + sum Q x) / (1 - q)``, the sum from 0
    in the entries' order (:meth:`mitld_lp.solvers.chain_levels.ChainLevels.solve`).
    One and two columns (a policy's values, and its values with its exit times: the
    greedy check's and the certificates' chains) by their own loops, the sums in
    scalars: the same operations in the same order as the general loop's (the same
    bits), 1.3x faster on QVBS ``zeroconf`` 1000-4's greedy chain (159,356 single
    states)."""
    k = x.shape[1]
    if k == 1:
        for i in range(order.shape[0]):
            s = order[i]
            a0 = 0.0
            for e in range(indptr[s], indptr[s + 1]):
                a0 += data[e] * x[indices[e], 0]
            x[s, 0] = (rhs[s, 0] + a0) / (1.0 - diag[s])
        return
    if k == 2:
        for i in range(order.shape[0]):
            s = order[i]
            a0 = a1 = 0.0
            for e in range(indptr[s], indptr[s + 1]):
                w = data[e]
                a0 += w * x[indices[e], 0]
                a1 += w * x[indices[e], 1]
            d = 1.0 - diag[s]
            x[s, 0] = (rhs[s, 0] + a0) / d
            x[s, 1] = (rhs[s, 1] + a1) / d
        return
    acc = np.empty(k)
    for i in range(order.shape[0]):
        s = order[i]
        for j in range(k):
            acc[j] = 0.0
        for e in range(indptr[s], indptr[s + 1]):
            t = indices[e]
            w = data[e]
            for j in range(k):
                acc[j] += w * x[t, j]
        for j in range(k):
            x[s, j] = (rhs[s, j] + acc[j]) / (1.0 - diag[s])


@numba.njit(cache=True, nogil=True)
def chain_flow(order, indptr, indices, data, diag, x):  # pragma: no cover - compiled
    """The single states ``order`` (upstream first) of a flow ``x = rhs + Q^T x``
    through a transient chain (``x`` holds ``rhs`` plus the inflow so far, a column per
    right-hand side): each state's inflow divided by ``1 - q``, then pushed along its
    row's entries but its own, in their order
    (:meth:`mitld_lp.solvers.chain_levels.ChainLevels.solve_transposed`).  One column
    by its own loop (the same operations in the same order: the same bits)."""
    k = x.shape[1]
    if k == 1:  # a flow from one start vector (the policy's): its own loop, as above
        for i in range(order.shape[0]):
            s = order[i]
            x[s, 0] /= 1.0 - diag[s]
            f = x[s, 0]
            for e in range(indptr[s], indptr[s + 1]):
                t = indices[e]
                if t != s:
                    x[t, 0] += data[e] * f
        return
    for i in range(order.shape[0]):
        s = order[i]
        for j in range(k):
            x[s, j] /= 1.0 - diag[s]
        for e in range(indptr[s], indptr[s + 1]):
            t = indices[e]
            if t != s:
                w = data[e]
                for j in range(k):
                    x[t, j] += w * x[s, j]

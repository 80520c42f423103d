"""A plain table world's breadth-first product levels as one compiled loop (numba).

Imported only by :mod:`mitld_lp.product.table_levels` (:class:`~mitld_lp.product.
table_levels.Compiled`), and only where the compiled load is paid or the product is
large or deep enough to pay it; compiled once, cached on disk, and run without importing
numba when its machine code is cached (:mod:`mitld_lp.util.kernel_loader`).

:func:`table_levels` expands the queue's states one after the other, as a breadth-first
search does, and gives exactly the arrays :meth:`~mitld_lp.product.table_levels.Plain.
expand` (ordinary states) and :func:`~mitld_lp.product.build._expand` (an absorbing
state's self-loop) give for the same states in batches:

* a new state is numbered when first met, in the order of the entries (state, choice,
  successor): the batched path numbers a batch's new keys by their first occurrence in
  the same order, so the numbering does not depend on where batches end;
* entries of one choice to one product state are summed in the order they come, the
  first's place kept (:func:`~mitld_lp.util.arrays.merge`): looked for only where two
  can meet (an absorbing state, or a table whose rows may repeat a state);
* the probabilities are the table's times the one outcome's (1.0: the same bits).
"""

from __future__ import annotations

from mitld_lp.util import kernel_loader

# numba's cached machine code run without importing numba; numba itself on a miss
numba = kernel_loader.lazy_numba(globals())

__all__ = ["table_levels"]


@numba.njit(cache=True, nogil=True)
def table_levels(keys, n_found, head, stop, cap, index, shift, act_start, act_count,
                 row_start, row_succ, row_prob, props, steps, step_bits, n_q, scale,
                 distinct, slot_aid, late, absorb, cols, vals, row_len, actions, choices,
                 out):  # pragma: no cover - compiled
    """Expand the queue's states ``keys[head:]`` (``n_found`` keys so far) up to state
    ``stop``, numbering new keys at ``keys[n_found:]`` and in ``index`` (by key +
    ``shift``); stops before a state whose entries might not fit the output arrays or
    ``keys``, might take the states found past ``cap``, or might name a key past the
    end of ``index`` (a dense array that grows by doubling, as the caller's).  Writes
    the rows' columns, values and lengths, the choices' actions (``late``: the choice's
    number plus ``late``, else ``slot_aid`` of it; ``absorb`` an absorbing state's) and
    the choices per state; ``out``: head, states found, entries, choices, states
    expanded, why it stopped (0: at ``stop`` or the queue's end, 1: the output arrays
    full, 2: ``keys`` full, 3: a key past ``index``, 4: ``cap`` reached) and, for 3,
    the index's length that state needs."""
    ne = 0
    nc = 0
    ns = 0
    why = 0
    need = 0
    n_index = index.shape[0]
    every = n_index >= act_start.shape[0] * n_q + shift  # the index holds every key
    while head < n_found and head < stop:
        key = keys[head]
        if key < 0:  # an absorbing state: its one self-loop
            if ne + 1 > cols.shape[0] or nc + 1 > row_len.shape[0] or ns + 1 > choices.shape[0]:
                why = 1
                break
            cols[ne] = head
            vals[ne] = 1.0
            ne += 1
            row_len[nc] = 1
            actions[nc] = absorb
            nc += 1
            choices[ns] = 1
            ns += 1
            head += 1
            continue
        g = key // n_q
        q = key - g * n_q
        c_lo = act_start[g]
        n_act = act_count[g]
        n_e = row_start[c_lo + n_act] - row_start[c_lo]
        if ne + n_e > cols.shape[0] or nc + n_act > row_len.shape[0] or ns + 1 > choices.shape[0]:
            why = 1
            break
        if n_found + n_e > keys.shape[0]:
            why = 2
            break
        if n_found + n_e > cap:
            why = 4
            break
        base = q << step_bits
        if not every:
            top = 0  # the index's length this state's successors need
            for e in range(row_start[c_lo], row_start[c_lo + n_act]):
                g2 = row_succ[e]
                q2 = steps[base | props[g2]]
                k2 = q2 if q2 < 0 else g2 * n_q + q2
                top = max(top, k2 + shift + 1)
            if top > n_index:
                why = 3
                need = top
                break
        for c in range(c_lo, c_lo + n_act):
            first = ne
            for e in range(row_start[c], row_start[c + 1]):
                g2 = row_succ[e]
                q2 = steps[base | props[g2]]
                k2 = q2 if q2 < 0 else g2 * n_q + q2
                i = index[k2 + shift]
                if i < 0:
                    i = n_found
                    index[k2 + shift] = i
                    keys[n_found] = k2
                    n_found += 1
                v = row_prob[e] * scale
                if q2 < 0 or not distinct:  # where two entries may meet: summed
                    j = first
                    while j < ne and cols[j] != i:
                        j += 1
                    if j < ne:
                        vals[j] += v
                        continue
                cols[ne] = i
                vals[ne] = v
                ne += 1
            row_len[nc] = ne - first
            actions[nc] = c + late if late > 0 else slot_aid[c]
            nc += 1
        choices[ns] = n_act
        ns += 1
        head += 1
    out[0] = head
    out[1] = n_found
    out[2] = ne
    out[3] = nc
    out[4] = ns
    out[5] = why
    out[6] = need

"""The own PRISM explorer's compiled loops (numba): one generic interpreter of the
bytecode of :mod:`mitld_lp.worlds.prism_compile`, compiled once and cached on disk (run
without importing numba when its machine code is cached: :mod:`mitld_lp.util.kernel_loader`),
never one kernel per model.

:func:`explore` is Storm's breadth-first exploration (``ExplicitModelBuilder`` with
``PrismNextStateGenerator``, its default options): a state is numbered when first met
(the initial state 0), in the order the choices list their successors (the module
docstring of :mod:`~mitld_lp.worlds.prism_compile`); an asynchronous command's updates
of probability 0 are skipped, a synchronised choice's branches are the products of its
commands' updates (in module order, ``p_k * (... * (p_1 * 1))``, a product of 0 cut off
as Storm cuts it), applied one after the other to the state with every expression read
in the state expanded; branches to one successor are summed in the order they come; a
state where the decided-states condition holds is not expanded (one self-loop), nor one
without an enabled command (a self-loop, flagged a deadlock).  Each choice's branches
are sorted by successor, as in Storm's sparse matrix.  It stops, with a status, at an
update out of a variable's range, a negative probability or the state budget (the caller
then lets Storm build, for Storm's own words, or refuses).
"""

from __future__ import annotations

import numpy as np

from mitld_lp.util import kernel_loader

numba = kernel_loader.lazy_numba(globals())

__all__ = ["explore", "label_flags", "OK", "OUT_OF_RANGE", "NEGATIVE", "BUDGET"]

OK, OUT_OF_RANGE, NEGATIVE, BUDGET = 0, 1, 2, 3
DEADLOCK_CHOICE, DECIDED_CHOICE = -1, -2


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _eval(code, consts, lo, hi, vals, stack):  # pragma: no cover - compiled
    """The value of the expression ``code[lo:hi]`` at the state ``vals``."""
    sp = 0
    pc = lo
    while pc < hi:
        op = code[pc]
        pc += 1
        if op == 0:  # CONST
            stack[sp] = consts[code[pc]]
            pc += 1
            sp += 1
        elif op == 1:  # LOAD
            stack[sp] = vals[code[pc]]
            pc += 1
            sp += 1
        elif op == 2:  # NOT
            stack[sp - 1] = 0.0 if stack[sp - 1] != 0.0 else 1.0
        elif op == 3:  # NEG
            stack[sp - 1] = -stack[sp - 1]
        elif op == 21:  # FLOOR
            stack[sp - 1] = np.floor(stack[sp - 1])
        elif op == 22:  # CEIL
            stack[sp - 1] = np.ceil(stack[sp - 1])
        elif op == 25:  # ITE
            sp -= 2
            stack[sp - 1] = stack[sp] if stack[sp - 1] != 0.0 else stack[sp + 1]
        else:
            sp -= 1
            a = stack[sp - 1]
            b = stack[sp]
            if op == 4:
                r = 1.0 if (a != 0.0 and b != 0.0) else 0.0
            elif op == 5:
                r = 1.0 if (a != 0.0 or b != 0.0) else 0.0
            elif op == 6:
                r = 1.0 if ((a != 0.0) != (b != 0.0)) else 0.0
            elif op == 7:
                r = 1.0 if (a == 0.0 or b != 0.0) else 0.0
            elif op == 8:
                r = 1.0 if ((a != 0.0) == (b != 0.0)) else 0.0
            elif op == 9:
                r = a + b
            elif op == 10:
                r = a - b
            elif op == 11:
                r = a * b
            elif op == 12:
                r = a / b
            elif op == 13:
                r = 1.0 if a == b else 0.0
            elif op == 14:
                r = 1.0 if a != b else 0.0
            elif op == 15:
                r = 1.0 if a < b else 0.0
            elif op == 16:
                r = 1.0 if a <= b else 0.0
            elif op == 17:
                r = 1.0 if a > b else 0.0
            elif op == 18:
                r = 1.0 if a >= b else 0.0
            elif op == 19:
                r = min(a, b)
            elif op == 20:
                r = max(a, b)
            elif op == 23:
                r = a ** b
            else:  # 24: MODULO
                r = np.fmod(a, b)
            stack[sp - 1] = r
    return stack[0]


@numba.njit(cache=True, nogil=True)
def _unpack(keys, at, words, word, shift, width, low, vals):  # pragma: no cover
    for v in range(vals.shape[0]):
        x = keys[at * words + word[v]]
        vals[v] = float(((x >> shift[v]) & ((np.int64(1) << width[v]) - 1)) + low[v])


@numba.njit(cache=True, nogil=True)
def _hash(buf, words):  # pragma: no cover - compiled
    h = np.uint64(1469598103934665603)
    for w in range(words):
        h ^= np.uint64(buf[w])
        h *= np.uint64(1099511628211)
        h ^= h >> np.uint64(29)
    return h


@numba.njit(cache=True, nogil=True)
def _grow_i(a, need):  # pragma: no cover - compiled
    if need <= a.shape[0]:
        return a
    b = np.empty(max(need, 2 * a.shape[0]), dtype=a.dtype)
    b[: a.shape[0]] = a
    return b


@numba.njit(cache=True, nogil=True)
def _grow_f(a, need):  # pragma: no cover - compiled
    if need <= a.shape[0]:
        return a
    b = np.empty(max(need, 2 * a.shape[0]), dtype=a.dtype)
    b[: a.shape[0]] = a
    return b


@numba.njit(cache=True, nogil=True)
def _assign(code, consts, starts, vals, stack, upd_assign, asg_var, asg_expr, u, buf,
            word, shift, width, low, high):  # pragma: no cover - compiled
    """Update ``u``'s assignments into the packed state ``buf``; False if one leaves
    its variable's range."""
    for k in range(upd_assign[u], upd_assign[u + 1]):
        v = asg_var[k]
        e = asg_expr[k]
        x = np.int64(_eval(code, consts, starts[e], starts[e + 1], vals, stack))
        if x < low[v] or x > high[v]:
            return False
        mask = ((np.int64(1) << width[v]) - 1) << shift[v]
        buf[word[v]] = (buf[word[v]] & ~mask) | ((x - low[v]) << shift[v])
    return True


@numba.njit(cache=True, nogil=True, error_model="numpy")
def explore(code, consts, starts, word, shift, width, low, high, initial, cmd_guard,
            cmd_updates, upd_prob, upd_assign, asg_var, asg_expr, n_async, sync_start,
            mod_start, sync_cmd, terminal, words, max_states):  # pragma: no cover
    """The breadth-first build (module docstring).  Returns ``(status, counts, keys,
    choices, branches, targets, probabilities, origin, combos)``: the packed states
    (``words`` int64 each), the offsets of each state's choices and each choice's
    branches, the branches, each choice's first command (or -1 a deadlock's self-loop,
    -2 a decided state's) and, for a synchronised choice, its commands at
    ``combos[origin_of ...]`` (see :func:`mitld_lp.worlds.prism_explore.explore_tables`);
    the arrays are longer than filled: ``counts`` (the second item) is ``(states, choices,
branches, combos)``, or the state and the command where a status other than OK stopped it."""
    nv = low.shape[0]
    vals = np.empty(nv, dtype=np.float64)
    stack = np.empty(max(16, code.shape[0]), dtype=np.float64)
    cap = 1 << 10
    keys = np.empty(cap * words, dtype=np.int64)
    tsize = 1 << 12
    table = np.full(tsize, -1, dtype=np.int64)
    choices = np.empty(cap + 1, dtype=np.int64)
    branches = np.empty(cap + 1, dtype=np.int64)
    targets = np.empty(cap, dtype=np.int64)
    probs = np.empty(cap, dtype=np.float64)
    origin = np.empty(cap, dtype=np.int64)
    combos = np.empty(cap, dtype=np.int64)  # a synchronised choice's commands, flat
    n_combo = 0
    buf = np.empty(words, dtype=np.int64)
    base = np.empty(words, dtype=np.int64)
    for w in range(words):
        buf[w] = 0
    for v in range(nv):
        buf[word[v]] |= (initial[v] - low[v]) << shift[v]
    for w in range(words):
        keys[w] = buf[w]
    table[_hash(buf, words) & np.uint64(tsize - 1)] = 0
    n = 1
    nc = 0
    nb = 0
    choices[0] = 0
    branches[0] = 0
    n_mods = 1
    for a in range(sync_start.shape[0] - 1):
        n_mods = max(n_mods, sync_start[a + 1] - sync_start[a])
    enabled = np.empty(cmd_guard.shape[0] + 1, dtype=np.int64)
    en_start = np.empty(n_mods + 1, dtype=np.int64)
    pick = np.empty(n_mods, dtype=np.int64)
    level_buf = np.empty((n_mods + 1) * words, dtype=np.int64)
    level_p = np.empty(n_mods + 1, dtype=np.float64)
    level_u = np.empty(n_mods + 1, dtype=np.int64)
    head = 0
    while head < n:
        _unpack(keys, head, words, word, shift, width, low, vals)
        for w in range(words):
            base[w] = keys[head * words + w]
        choices = _grow_i(choices, head + 2)
        first_choice = nc
        expand = True
        if terminal >= 0:
            if _eval(code, consts, starts[terminal], starts[terminal + 1], vals, stack) != 0.0:
                expand = False
        if expand:
            for c in range(n_async):
                g = cmd_guard[c]
                if _eval(code, consts, starts[g], starts[g + 1], vals, stack) == 0.0:
                    continue
                branches = _grow_i(branches, nc + 2)
                origin = _grow_i(origin, nc + 1)
                row = nb
                for u in range(cmd_updates[c], cmd_updates[c + 1]):
                    e = upd_prob[u]
                    p = _eval(code, consts, starts[e], starts[e + 1], vals, stack)
                    if p == 0.0:
                        continue
                    if p < 0.0:
                        return NEGATIVE, (head, c, 0, 0), keys, choices, branches, targets, probs, origin, combos
                    for w in range(words):
                        buf[w] = base[w]
                    if not _assign(code, consts, starts, vals, stack, upd_assign, asg_var,
                                   asg_expr, u, buf, word, shift, width, low, high):
                        return OUT_OF_RANGE, (head, c, 0, 0), keys, choices, branches, targets, probs, origin, combos
                    # the successor's number (a new state appended)
                    slot = _hash(buf, words) & np.uint64(table.shape[0] - 1)
                    t = -1
                    while table[slot] >= 0:
                        s = table[slot]
                        same = True
                        for w in range(words):
                            if keys[s * words + w] != buf[w]:
                                same = False
                                break
                        if same:
                            t = s
                            break
                        slot = (slot + np.uint64(1)) & np.uint64(table.shape[0] - 1)
                    if t < 0:
                        if n >= max_states:
                            return BUDGET, (head, c, 0, 0), keys, choices, branches, targets, probs, origin, combos
                        keys = _grow_i(keys, (n + 1) * words)
                        for w in range(words):
                            keys[n * words + w] = buf[w]
                        table[slot] = n
                        t = n
                        n += 1
                        if 2 * n > table.shape[0]:
                            table = _rehash(keys, n, words, 2 * table.shape[0])
                    j = row
                    while j < nb and targets[j] != t:
                        j += 1
                    if j < nb:
                        probs[j] += p
                    else:
                        targets = _grow_i(targets, nb + 1)
                        probs = _grow_f(probs, nb + 1)
                        targets[nb] = t
                        probs[nb] = p
                        nb += 1
                _sort_row(targets, probs, row, nb)
                origin[nc] = c
                nc += 1
                branches[nc] = nb
            for a in range(sync_start.shape[0] - 1):
                k = sync_start[a + 1] - sync_start[a]
                ok = True
                en_start[0] = 0
                ne = 0
                for j in range(k):
                    slot_m = sync_start[a] + j
                    for i in range(mod_start[slot_m], mod_start[slot_m + 1]):
                        c = sync_cmd[i]
                        g = cmd_guard[c]
                        if _eval(code, consts, starts[g], starts[g + 1], vals, stack) != 0.0:
                            enabled[ne] = c
                            ne += 1
                    en_start[j + 1] = ne
                    if ne == en_start[j]:
                        ok = False
                        break
                if not ok:
                    continue
                for j in range(k):
                    pick[j] = en_start[j]
                while True:  # each combination, the last module's command fastest
                    branches = _grow_i(branches, nc + 2)
                    origin = _grow_i(origin, nc + 1)
                    combos = _grow_i(combos, n_combo + k)
                    origin[nc] = -3 - n_combo
                    for j in range(k):
                        combos[n_combo + j] = enabled[pick[j]]
                    n_combo += k
                    row = nb
                    # depth first over the updates: level j applies module j's update
                    for w in range(words):
                        level_buf[w] = base[w]
                    level_p[0] = 1.0
                    lev = 0
                    level_u[0] = cmd_updates[enabled[pick[0]]] - 1
                    while lev >= 0:
                        c = enabled[pick[lev]]
                        level_u[lev] += 1
                        u = level_u[lev]
                        if u >= cmd_updates[c + 1]:
                            lev -= 1
                            continue
                        e = upd_prob[u]
                        q = _eval(code, consts, starts[e], starts[e + 1], vals, stack)
                        if q < 0.0:
                            return NEGATIVE, (head, c, 0, 0), keys, choices, branches, targets, probs, origin, combos
                        q = q * level_p[lev]
                        for w in range(words):
                            level_buf[(lev + 1) * words + w] = level_buf[lev * words + w]
                        if not _assign(code, consts, starts, vals, stack, upd_assign, asg_var,
                                       asg_expr, u, level_buf[(lev + 1) * words:(lev + 2) * words],
                                       word, shift, width, low, high):
                            return OUT_OF_RANGE, (head, c, 0, 0), keys, choices, branches, targets, probs, origin, combos
                        if q == 0.0:
                            continue
                        if lev + 1 < k:
                            lev += 1
                            level_p[lev] = q
                            level_u[lev] = cmd_updates[enabled[pick[lev]]] - 1
                            continue
                        for w in range(words):
                            buf[w] = level_buf[k * words + w]
                        slot = _hash(buf, words) & np.uint64(table.shape[0] - 1)
                        t = -1
                        while table[slot] >= 0:
                            s = table[slot]
                            same = True
                            for w in range(words):
                                if keys[s * words + w] != buf[w]:
                                    same = False
                                    break
                            if same:
                                t = s
                                break
                            slot = (slot + np.uint64(1)) & np.uint64(table.shape[0] - 1)
                        if t < 0:
                            if n >= max_states:
                                return BUDGET, (head, c, 0, 0), keys, choices, branches, targets, probs, origin, combos
                            keys = _grow_i(keys, (n + 1) * words)
                            for w in range(words):
                                keys[n * words + w] = buf[w]
                            table[slot] = n
                            t = n
                            n += 1
                            if 2 * n > table.shape[0]:
                                table = _rehash(keys, n, words, 2 * table.shape[0])
                        j = row
                        while j < nb and targets[j] != t:
                            j += 1
                        if j < nb:
                            probs[j] += q
                        else:
                            targets = _grow_i(targets, nb + 1)
                            probs = _grow_f(probs, nb + 1)
                            targets[nb] = t
                            probs[nb] = q
                            nb += 1
                    _sort_row(targets, probs, row, nb)
                    nc += 1
                    branches[nc] = nb
                    j = k - 1
                    while j >= 0:
                        pick[j] += 1
                        if pick[j] < en_start[j + 1]:
                            break
                        pick[j] = en_start[j]
                        j -= 1
                    if j < 0:
                        break
        if nc == first_choice:  # not expanded, or no command enabled: a self-loop
            branches = _grow_i(branches, nc + 2)
            origin = _grow_i(origin, nc + 1)
            targets = _grow_i(targets, nb + 1)
            probs = _grow_f(probs, nb + 1)
            targets[nb] = head
            probs[nb] = 1.0
            nb += 1
            origin[nc] = DEADLOCK_CHOICE if expand else DECIDED_CHOICE
            nc += 1
            branches[nc] = nb
        head += 1
        choices[head] = nc
    return OK, (n, nc, nb, n_combo), keys, choices, branches, targets, probs, origin, combos


@numba.njit(cache=True, nogil=True)
def _rehash(keys, n, words, size):  # pragma: no cover - compiled
    table = np.full(size, -1, dtype=np.int64)
    mask = np.uint64(size - 1)
    for s in range(n):
        slot = _hash(keys[s * words:(s + 1) * words], words) & mask
        while table[slot] >= 0:
            slot = (slot + np.uint64(1)) & mask
        table[slot] = s
    return table


@numba.njit(cache=True, nogil=True)
def _sort_row(targets, probs, lo, hi):  # pragma: no cover - compiled
    """Insertion sort of the branches ``lo:hi`` by successor (a few a row)."""
    for i in range(lo + 1, hi):
        t = targets[i]
        p = probs[i]
        j = i - 1
        while j >= lo and targets[j] > t:
            targets[j + 1] = targets[j]
            probs[j + 1] = probs[j]
            j -= 1
        targets[j + 1] = t
        probs[j + 1] = p


@numba.njit(cache=True, nogil=True, error_model="numpy")
def label_flags(code, consts, starts, keys, words, word, shift, width, low,
                exprs):  # pragma: no cover - compiled
    """Each state's truth of each expression ``exprs`` (``n x len(exprs)`` flags)."""
    n = keys.shape[0] // words
    out = np.zeros((n, exprs.shape[0]), dtype=np.bool_)
    vals = np.empty(low.shape[0], dtype=np.float64)
    stack = np.empty(max(16, code.shape[0]), dtype=np.float64)
    for s in range(n):
        _unpack(keys, s, words, word, shift, width, low, vals)
        for k in range(exprs.shape[0]):
            e = exprs[k]
            out[s, k] = _eval(code, consts, starts[e], starts[e + 1], vals, stack) != 0.0
    return out

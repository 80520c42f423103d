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

__all__ = ["explore", "rehash", "label_flags", "OK", "OUT_OF_RANGE", "NEGATIVE", "BUDGET",
           "FULL", "REHASH"]

OK, OUT_OF_RANGE, NEGATIVE, BUDGET, FULL, REHASH = 0, 1, 2, 3, 4, 5
DEADLOCK_CHOICE, DECIDED_CHOICE = -1, -2


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
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
        elif op == 26:  # COMPARE v k r: a variable against a constant
            a = vals[code[pc]]
            b = consts[code[pc + 1]]
            r = code[pc + 2]
            pc += 3
            if r == 13:
                t = a == b
            elif r == 14:
                t = a != b
            elif r == 15:
                t = a < b
            elif r == 16:
                t = a <= b
            elif r == 17:
                t = a > b
            else:
                t = a >= b
            stack[sp] = 1.0 if t else 0.0
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


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _enabled(code, consts, starts, conj, cmd_guard, c, vals, stack):  # pragma: no cover
    """Whether command ``c``'s guard holds: its conjuncts in turn, the first false ends."""
    for i in range(cmd_guard[c], cmd_guard[c + 1]):
        e = conj[i]
        if _eval(code, consts, starts[e], starts[e + 1], vals, stack) == 0.0:
            return False
    return True


@numba.njit(cache=True, nogil=True, inline="always")
def _unpack(keys, at, words, word, shift, width, low, vals):  # pragma: no cover
    for v in range(vals.shape[0]):
        x = keys[at * words + word[v]]
        vals[v] = float(((x >> shift[v]) & ((np.int64(1) << width[v]) - 1)) + low[v])


@numba.njit(cache=True, nogil=True, inline="always")
def _hash(buf, words):  # pragma: no cover - compiled
    """A 64-bit mix of the packed state (splitmix64's finaliser over its words)."""
    h = np.uint64(0x9E3779B97F4A7C15)
    for w in range(words):
        h ^= np.uint64(buf[w])
        h ^= h >> np.uint64(30)
        h *= np.uint64(0xBF58476D1CE4E5B9)
        h ^= h >> np.uint64(27)
        h *= np.uint64(0x94D049BB133111EB)
        h ^= h >> np.uint64(31)
    return h


@numba.njit(cache=True, nogil=True, inline="always")
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


@numba.njit(cache=True, nogil=True, inline="always")
def _number(buf, words, keys, table, pos, max_states):  # pragma: no cover - compiled
    """The number of the packed state ``buf``, appended (``pos[1]`` states) when new;
    -1 past ``max_states``, -2 when ``keys`` is full, -3 when the table must grow."""
    mask = np.uint64(table.shape[0] - 1)
    slot = _hash(buf, words) & mask
    while table[slot] >= 0:
        s = table[slot]
        same = True
        for w in range(words):
            if keys[s * words + w] != buf[w]:
                same = False
                break
        if same:
            return s
        slot = (slot + np.uint64(1)) & mask
    n = pos[1]
    if n >= max_states:
        return -1
    if (n + 1) * words > keys.shape[0]:
        return -2
    if 2 * (n + 1) > table.shape[0]:
        return -3
    for w in range(words):
        keys[n * words + w] = buf[w]
    table[slot] = n
    pos[1] = n + 1
    return n


@numba.njit(cache=True, nogil=True, inline="always")
def _add(targets, probs, row, nb, t, p):  # pragma: no cover - compiled
    """Branch ``(t, p)`` into the row from ``row`` (``nb`` branches so far), summed onto
    an earlier one to ``t``; the new count, or -1 when ``targets`` is full."""
    j = row
    while j < nb and targets[j] != t:
        j += 1
    if j < nb:
        probs[j] += p
        return nb
    if nb >= targets.shape[0]:
        return -1
    targets[nb] = t
    probs[nb] = p
    return nb + 1


@numba.njit(cache=True, nogil=True, inline="always")
def _branch(buf, words, keys, table, pos, max_states, targets, probs, row, nb,
            p):  # pragma: no cover - compiled
    """The successor ``buf`` numbered (:func:`_number`) and its branch added to the row
    (:func:`_add`): ``(status, branches)``, the count unchanged when not OK."""
    t = _number(buf, words, keys, table, pos, max_states)
    if t < 0:
        return (BUDGET if t == -1 else (FULL if t == -2 else REHASH)), nb
    added = _add(targets, probs, row, nb, t, p)
    if added < 0:
        return FULL, nb
    return OK, added


@numba.njit(cache=True, nogil=True, error_model="numpy")
def explore(code, consts, starts, word, shift, width, low, high, initial, cmd_guard, conj,
            cmd_updates, upd_prob, upd_assign, asg_var, asg_expr, n_async, sync_start,
            mod_start, sync_cmd, sync_base, terminal, words, max_states, keys, table,
            choices, branches, targets, probs, origin, pos):  # pragma: no cover
    """The breadth-first build (module docstring) into the caller's arrays, from
    ``pos`` = ``(head, states, choices, branches, -, state, command)`` on, until done
    (:data:`OK`) or stopped: :data:`FULL` (an output array or ``keys`` too short: the
    caller grows them and calls again, the state at ``head`` expanded afresh: the states
    it found are kept, and found again in the same order), :data:`REHASH` (the table
    must grow: :func:`rehash`), or a refusal (its state and command in ``pos[5:7]``).
    ``keys``: the packed states (``words`` int64 each); ``choices``/``branches``: the
    offsets of each state's choices and each choice's branches (``table``: int32 slots,
    -1 free); ``origin``: each choice's command (-1 a deadlock's self-loop, -2 a decided
    state's, ``-3 - i``: a synchronised choice of action ``a``, ``i = sync_base[a] + r``
    with ``r`` its commands' positions in their modules' lists of the action's commands
    as the digits of a mixed-radix number, the first module's the highest: one number a
    choice, no list of its commands kept)."""
    vals = np.empty(low.shape[0], dtype=np.float64)
    stack = np.empty(max(16, code.shape[0]), dtype=np.float64)
    buf = np.empty(words, dtype=np.int64)
    base = np.empty(words, dtype=np.int64)
    if pos[1] == 0:  # the initial state
        for w in range(words):
            buf[w] = 0
        for v in range(low.shape[0]):
            buf[word[v]] |= (initial[v] - low[v]) << shift[v]
        _number(buf, words, keys, table, pos, max_states)
        choices[0] = 0
        branches[0] = 0
    n_mods = 1
    for a in range(sync_start.shape[0] - 1):
        n_mods = max(n_mods, sync_start[a + 1] - sync_start[a])
    enabled = np.empty(max(1, cmd_guard.shape[0]), dtype=np.int64)
    en_pos = np.empty(max(1, cmd_guard.shape[0]), dtype=np.int64)
    en_start = np.empty(n_mods + 1, dtype=np.int64)
    pick = np.empty(n_mods, dtype=np.int64)
    level_buf = np.empty((n_mods + 1) * words, dtype=np.int64)
    level_p = np.empty(n_mods + 1, dtype=np.float64)
    level_u = np.empty(n_mods + 1, dtype=np.int64)
    head = pos[0]
    nc = pos[2]
    nb = pos[3]
    status = OK
    while head < pos[1]:
        nc0 = nc
        nb0 = nb
        if head + 2 > choices.shape[0]:
            status = FULL
            break
        _unpack(keys, head, words, word, shift, width, low, vals)
        for w in range(words):
            base[w] = keys[head * words + w]
        expand = True
        if terminal >= 0:
            if _eval(code, consts, starts[terminal], starts[terminal + 1], vals, stack) != 0.0:
                expand = False
        c = 0
        if expand:
            for c in range(n_async):
                if not _enabled(code, consts, starts, conj, cmd_guard, c, vals, stack):
                    continue
                if nc + 2 > branches.shape[0] or nc + 1 > origin.shape[0]:
                    status = FULL
                    break
                row = nb
                for u in range(cmd_updates[c], cmd_updates[c + 1]):
                    e = upd_prob[u]
                    p = _eval(code, consts, starts[e], starts[e + 1], vals, stack)
                    if p == 0.0:
                        continue
                    if p < 0.0:
                        status = NEGATIVE
                        break
                    for w in range(words):
                        buf[w] = base[w]
                    if not _assign(code, consts, starts, vals, stack, upd_assign, asg_var,
                                   asg_expr, u, buf, word, shift, width, low, high):
                        status = OUT_OF_RANGE
                        break
                    status, nb = _branch(buf, words, keys, table, pos, max_states, targets,
                                         probs, row, nb, p)
                    if status != OK:
                        break
                if status != OK:
                    break
                _sort_row(targets, probs, row, nb)
                origin[nc] = c
                nc += 1
                branches[nc] = nb
            a = 0
            while status == OK and a < sync_start.shape[0] - 1:
                k = sync_start[a + 1] - sync_start[a]
                ok = True
                en_start[0] = 0
                ne = 0
                for j in range(k):
                    slot_m = sync_start[a] + j
                    for i in range(mod_start[slot_m], mod_start[slot_m + 1]):
                        c = sync_cmd[i]
                        if _enabled(code, consts, starts, conj, cmd_guard, c, vals, stack):
                            enabled[ne] = c
                            en_pos[ne] = i - mod_start[slot_m]
                            ne += 1
                    en_start[j + 1] = ne
                    if ne == en_start[j]:
                        ok = False
                        break
                a += 1
                if not ok:
                    continue
                for j in range(k):
                    pick[j] = en_start[j]
                while status == OK:  # each combination, the last module's fastest
                    if nc + 2 > branches.shape[0] or nc + 1 > origin.shape[0]:
                        status = FULL
                        break
                    r = np.int64(0)
                    for j in range(k):
                        slot_m = sync_start[a - 1] + j
                        r = r * (mod_start[slot_m + 1] - mod_start[slot_m]) + en_pos[pick[j]]
                    origin[nc] = -3 - (sync_base[a - 1] + r)
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
                            status = NEGATIVE
                            break
                        q = q * level_p[lev]
                        for w in range(words):
                            buf[w] = level_buf[lev * words + w]
                        if not _assign(code, consts, starts, vals, stack, upd_assign, asg_var,
                                       asg_expr, u, buf, word, shift, width, low, high):
                            status = OUT_OF_RANGE
                            break
                        if q == 0.0:
                            continue
                        if lev + 1 < k:
                            lev += 1
                            for w in range(words):
                                level_buf[lev * words + w] = buf[w]
                            level_p[lev] = q
                            level_u[lev] = cmd_updates[enabled[pick[lev]]] - 1
                            continue
                        status, nb = _branch(buf, words, keys, table, pos, max_states,
                                             targets, probs, row, nb, q)
                        if status != OK:
                            break
                    if status != OK:
                        break
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
        if status == OK and nc == nc0:  # not expanded, or no command enabled: a self-loop
            if nc + 2 > branches.shape[0] or nc + 1 > origin.shape[0] or \
                    nb + 1 > targets.shape[0]:
                status = FULL
            else:
                targets[nb] = head
                probs[nb] = 1.0
                nb += 1
                origin[nc] = DEADLOCK_CHOICE if expand else DECIDED_CHOICE
                nc += 1
                branches[nc] = nb
        if status != OK:  # this state again from its start, after the caller's work
            nc = nc0
            nb = nb0
            pos[5] = head
            pos[6] = c
            break
        head += 1
        choices[head] = nc
    pos[0] = head
    pos[2] = nc
    pos[3] = nb
    return status


@numba.njit(cache=True, nogil=True)
def rehash(keys, n, words, size):  # pragma: no cover - compiled
    """The hash table of the first ``n`` packed states of ``keys``, ``size`` slots
    (int32: a build has fewer than 2**31 states)."""
    table = np.full(size, -1, dtype=np.int32)
    mask = np.uint64(size - 1)
    for s in range(n):
        slot = _hash(keys[s * words:(s + 1) * words], words) & mask
        while table[slot] >= 0:
            slot = (slot + np.uint64(1)) & mask
        table[slot] = s
    return table


@numba.njit(cache=True, nogil=True, inline="always")
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

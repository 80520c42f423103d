"""The numba kernel of the repair's rounds on a large level
(:meth:`~mitld_lp.solvers.certify_repair.Repair.run`), run through
:mod:`mitld_lp.util.kernel_loader` and only where its cache file is there and a
compiled kernel's load is paid (:func:`~mitld_lp.solvers.certify_compiled.
compiled_rounds`).  A module of its own: an edit here does not make the Bellman
check's kernels (:mod:`mitld_lp.solvers.certify_kernels`) stale in the loader's cache;
the repair's needs outside the rounds (:func:`state_needs`) are here too, beside the
arithmetic they share.

:func:`level_rounds` makes the rounds the NumPy code makes on one level, in one call:
per round the needs of the states to do (:func:`_need`, the one copy of the need's
arithmetic, which :func:`state_needs` runs for the repair's other calls: the same
operations on the same operands as the NumPy need, so the same bits),
all read before any bound moves (as the NumPy round reads them), then the moves, then
the level's readers of the moved states as the next round's states to do (the matrix's
pattern by column, :func:`~mitld_lp.solvers.certify_repair.readers_by_column`).  So the
same bounds, the same count of moves and the same verdict (a level still moving after
``rounds`` rounds does not settle).

A worklist (a queue of the states to read, a move queueing its readers, each read from
the freshest bounds) reaches the same least fixed point of the same monotone map from
the same start, so the same bits where both settle (measured so on QVBS zeroconf
1000-4: 31,694 moves against the rounds' 36,454); it was slower there (39-47 ms CPU
against the rounds' 25-28 ms in one process: its reads jump about the level in queue
order, the rounds read each round's states in ascending order), so the rounds stay."""

from __future__ import annotations

import numpy as np

from mitld_lp.util import kernel_loader

# numba's cached machine code run without importing numba; numba itself on a miss
numba = kernel_loader.lazy_numba(globals())

__all__ = ["level_rounds", "state_needs"]


@numba.njit(cache=True, nogil=True, inline="always")
def _rows_of(c, nature, has_nature):  # pragma: no cover - compiled
    """Choice ``c``'s rows ``lo, hi``: nature's where given, else the row ``c``."""
    if has_nature:
        return nature[c], nature[c + 1]
    return c, c + 1


@numba.njit(cache=True, nogil=True, inline="always")
def _need(s, groups, nature, has_nature, indptr, indices, data, x, count, slack_of,
          factor_of, upper):  # pragma: no cover - compiled
    """State ``s``'s need (each with a choice, each choice with a row), what the
    repair's :func:`~mitld_lp.solvers.certify_repair._need_of` computes: per row the
    rounded bound of its float sum (:func:`~mitld_lp.solvers.certify_kernels.
    bellman_rows`' arithmetic) capped by the extreme of ``x`` over its stored entries
    (``min`` of the two above, ``max`` below), the least over a choice's rows (nature's
    pick), and the largest (``upper``) or least over the state's choices.  The one
    copy of that arithmetic: :func:`state_needs` and :func:`level_rounds` both call it."""
    best = -np.inf if upper else np.inf
    for c in range(groups[s], groups[s + 1]):
        lo, hi = _rows_of(c, nature, has_nature)
        pick = np.inf
        for r in range(lo, hi):
            acc = 0.0
            for e in range(indptr[r], indptr[r + 1]):
                acc += data[e] * x[indices[e]]
            f = count[r]
            if upper:
                each = (acc + slack_of[f]) * factor_of[f]
                ext = -np.inf
                for e in range(indptr[r], indptr[r + 1]):
                    v = x[indices[e]]
                    if v > ext:
                        ext = v
                if ext < each:
                    each = ext
            else:
                each = (acc - slack_of[f]) * factor_of[f]
                if each < 0.0:
                    each = 0.0
                ext = np.inf
                for e in range(indptr[r], indptr[r + 1]):
                    v = x[indices[e]]
                    if v < ext:
                        ext = v
                if ext > each:
                    each = ext
            if each < pick:
                pick = each
        if upper:
            if pick > best:
                best = pick
        elif pick < best:
            best = pick
    return best


@numba.njit(cache=True, nogil=True, inline="always")
def _convex_passes(r, indptr, indices, x, own, upper):  # pragma: no cover - compiled
    """Whether row ``r`` passes by the convex rule: the largest ``x`` over its stored
    entries at most ``own`` (``upper``), the least at least ``own`` (an empty row's
    extreme is -inf / inf: it passes).  Every entry read: a return at the first entry
    past ``own`` made the kernel several times slower (numba, measured)."""
    ext = -np.inf if upper else np.inf
    for e in range(indptr[r], indptr[r + 1]):
        v = x[indices[e]]
        if (v > ext) if upper else (v < ext):
            ext = v
    return (ext <= own) if upper else (ext >= own)


@numba.njit(cache=True, nogil=True, inline="always")
def _state_fails(s, groups, nature, has_nature, indptr, indices, data, x, count,
                 slack_of, factor_of, upper, rule_first):  # pragma: no cover - compiled
    """Whether state ``s`` (each choice with a row) fails the pre- (``upper``) or
    sub-fixed point check of :func:`~mitld_lp.solvers.certify_kernels.bellman_rows`: the
    same comparisons on the same operands (a row passes when its rounded bound, at least
    0 below, is on the right side of ``x[s]``, or else by :func:`_convex_passes`; a
    choice when one of its rows does; the state when every choice does), stopping at a
    choice's first passing row and at the first failing choice.  ``rule_first``: the
    convex rule read before the sum (a row passes when either does, so the same
    verdict): for a state at ``x``'s far extreme (1 below, 0 above on QVBS products),
    where the sum's rounded bound cannot reach its value and only the rule passes, its
    entries read once, not twice."""
    own = x[s]
    for c in range(groups[s], groups[s + 1]):
        lo, hi = _rows_of(c, nature, has_nature)
        passed = False
        for r in range(lo, hi):
            if rule_first and _convex_passes(r, indptr, indices, x, own, upper):
                passed = True
                break
            acc = 0.0
            for e in range(indptr[r], indptr[r + 1]):
                acc += data[e] * x[indices[e]]
            f = count[r]
            if upper:
                passed = (acc + slack_of[f]) * factor_of[f] <= own
            else:
                bound = (acc - slack_of[f]) * factor_of[f]
                passed = (bound if bound > 0.0 else 0.0) >= own
            if passed:
                break
            if not rule_first and _convex_passes(r, indptr, indices, x, own, upper):
                passed = True
                break
        if not passed:
            return True
    return False


@numba.njit(cache=True, nogil=True)
def state_needs(states, groups, nature, indptr, indices, data, x, count, slack_of,
                factor_of, upper, out, verdict):  # pragma: no cover - compiled
    """Per state of ``states`` (each with a choice, each choice with a row), its need
    (:func:`_need`), written into ``out``: what the repair's NumPy
    :func:`~mitld_lp.solvers.certify_repair._needed` gives, the same operations on the
    same operands.  ``verdict``: instead of the need, +inf where the state fails the
    pre- (``upper``, :func:`_fails_above`) or sub-fixed point check
    (:func:`_fails_below`) and -inf where it passes: the Bellman check's verdict a
    state at a time, so that a certificate's check and its repair link this one
    kernel, and no verdict a row is held and reduced over the choices after."""
    has_nature = nature.shape[0] > 0
    if verdict:
        # ``x``'s extreme on the passing side: a state whose own value is past it (at
        # least the largest ``x`` above, at most the least below) passes every row by
        # the convex rule, whatever its float sums (the largest ``x`` over a support
        # is at most ``x``'s largest), so its rows are not read: the same verdict, as
        # NumPy's rule settles those rows (:func:`~mitld_lp.solvers.certify.
        # _rule_values`: a maximum's states at 1); a state at the other extreme reads
        # the rule first (:func:`_state_fails`).  On the QVBS products, whose states
        # are mostly at 0 or 1: the check 2-3x faster (docs/results.md, cert-84)
        near = far = x[0] if x.shape[0] else 0.0  # the passing side's extreme, the other
        for j in range(x.shape[0]):
            v = x[j]
            if (v > near) if upper else (v < near):
                near = v
            if (v < far) if upper else (v > far):
                far = v
        for i in range(states.shape[0]):
            own = x[states[i]]
            if (own >= near) if upper else (own <= near):
                out[i] = -np.inf
                continue
            failed = _state_fails(states[i], groups, nature, has_nature, indptr, indices,
                                  data, x, count, slack_of, factor_of, upper, own == far)
            out[i] = np.inf if failed else -np.inf
        return
    for i in range(states.shape[0]):
        out[i] = _need(states[i], groups, nature, has_nature, indptr, indices, data, x,
                       count, slack_of, factor_of, upper)


@numba.njit(cache=True, nogil=True)
def level_rounds(mine, todo, groups, nature, indptr, indices, data, x, count, slack_of,
                 factor_of, upper, col_ptr, col_state, rounds, moved,
                 out, at):  # pragma: no cover - compiled
    """The repair's rounds on the level's states ``mine`` (each with a choice, each
    choice with a row), from the states to do ``todo`` (a flag per state of ``mine``,
    overwritten), at most ``rounds`` rounds: per round the needs of those to do from
    ``x`` as it stands, then each bound its need passes moved to it (at most 1 above, at
    least 0 below), then the states of ``mine`` reading a moved one to do next.  Every
    moved state is flagged in ``moved`` (a flag a state of the model).  ``out[0]``: the
    moves made (a state once a round it moves in), ``out[1]``: 1 where the level
    settled (a round with none to do or none moved), 0 where it still moved after
    ``rounds`` rounds.  ``groups``: each state's first choice; ``nature``: each
    choice's first row (empty: a row a choice).  ``at``: a scratch int64 a state,
    -1 everywhere on entry and so again on return (each state's place in ``mine``
    while the rounds run): not a map of the model's size made a call."""
    m = mine.shape[0]
    has_nature = nature.shape[0] > 0
    for i in range(m):
        at[mine[i]] = i
    doing = np.empty(m, dtype=np.int64)
    need = np.empty(m)
    changed = np.empty(m, dtype=np.int64)
    moves = 0
    settled = 0
    for _r in range(rounds):
        k = 0
        for i in range(m):
            if todo[i]:
                doing[k] = mine[i]
                k += 1
        if k == 0:
            settled = 1
            break
        for j in range(k):  # every need read before any bound moves
            need[j] = _need(doing[j], groups, nature, has_nature, indptr, indices, data,
                            x, count, slack_of, factor_of, upper)
        c = 0
        for j in range(k):
            s = doing[j]
            if upper:
                if need[j] > x[s]:
                    x[s] = need[j] if need[j] < 1.0 else 1.0
                    changed[c] = s
                    c += 1
            elif need[j] < x[s]:
                x[s] = need[j] if need[j] > 0.0 else 0.0
                changed[c] = s
                c += 1
        if c == 0:
            settled = 1
            break
        moves += c
        for i in range(m):
            todo[i] = False
        for j in range(c):
            s = changed[j]
            moved[s] = True
            for e in range(col_ptr[s], col_ptr[s + 1]):
                p = at[col_state[e]]
                if p >= 0:
                    todo[p] = True
    for i in range(m):
        at[mine[i]] = -1
    out[0] = moves
    out[1] = settled


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

__all__ = ["CHECK_BATCH", "COMPILED_CHECK_MIN_ROWS", "CYCLING_MIN_STATES",
           "WARM_LOAD_MIN_ENTRIES", "compiled_chain_parts", "compiled_chain_sets",
           "compiled_checks",
           "compiled_cycling", "compiled_failing", "compiled_needs", "compiled_rounds",
           "load_if_warm", "rounds_cached"]

CHECK_BATCH = 1 << 16
"""States whose rows one call of the compiled Bellman check reads, where it checks
every state (:func:`compiled_checks`: its index of states, its memory bound)."""

COMPILED_CHECK_MIN_ROWS = 20_000
"""The fewest rows whose Bellman check (:func:`compiled_checks`) runs compiled, once a
compiled kernel's load is paid (the kernel's own first read, about 2 ms, against the
NumPy check's 10-20 ns a row and its dozen calls a batch)."""


WARM_LOAD_MIN_ENTRIES = 150_000
"""The fewest stored entries of a model whose certificate pays the compiled kernels'
load itself where it is the loader's cheap one (:func:`load_if_warm`): inside a solve
the load measured 5-10 ms of CPU (the cache look-ups, the loader's pieces), then about
1 ms a kernel's first call, against the NumPy Bellman check's 13-18 ms on QVBS
firewire_dl 3-600 (197,013 entries) and csma 4-2 (1.09 million), which the compiled
check does in 1-4 ms, beside the chain's sets and its single states over many levels.
On QVBS consensus 4-4 (144,349 entries) the load cost what it saved (a minimum's
attractor test, 15-20 ms of NumPy rounds, 3-8 ms compiled): not paid there."""

WARM_KERNELS = (("mitld_lp.solvers.certify_kernels", "bellman_rows"),
                ("mitld_lp.solvers.certify_kernels", "chain_parts"),
                ("mitld_lp.solvers.level_kernels", "chain_values"),
                ("mitld_lp.solvers.compiled_graph", "_backward"))
"""The kernels a certificate runs once the load is paid, one or two of each module
(the Bellman check and the chain's sets, the chain's single states, a minimum's
attractor): :func:`load_if_warm` pays it only where each has a cache file, so that a
cold one never makes a certificate pay numba's compile it would not otherwise pay.
Each look-up reads a cache directory (0.3-0.6 ms: the seven of every kernel the
certificate may run were some 4 ms of QVBS consensus 4-4's 9 ms load); a module's
kernels are compiled by the same certificates, so one stands for the others."""

_WARM: list[bool] = []  # whether every kernel of WARM_KERNELS is cached, once a process


def load_if_warm(entries: int) -> bool:
    """Whether the compiled kernels' load is paid for a certificate of a model with
    ``entries`` stored entries, paying it (:func:`~mitld_lp.util.kernel_loader.prepare`)
    where it was not and it is cheap: at least :data:`WARM_LOAD_MIN_ENTRIES` entries and
    every kernel of :data:`WARM_KERNELS` linked from the loader's cache (the loader on,
    numba installed, a cache file there: :func:`~mitld_lp.util.kernel_loader.cached`).
    The gates of the certificate's compiled paths ask
    :func:`~mitld_lp.util.kernel_loader.compiled_paid` after; every compiled path gives
    the NumPy path's bits, so only the time differs."""
    if kernel_loader.compiled_paid():
        return True
    if entries < WARM_LOAD_MIN_ENTRIES:
        return False
    if not _WARM:
        _WARM.append(all(kernel_loader.module_cached(module, name)
                         for module, name in WARM_KERNELS))
    if not _WARM[0]:
        return False
    kernel_loader.prepare()
    return kernel_loader.compiled_paid()


def _checked_arrays(st: Any, x: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The states' first choices and the choices' first rows (empty: a row a choice),
    int64, where the compiled Bellman check may run on ``st`` and ``x``; None where
    not: fewer than :data:`COMPILED_CHECK_MIN_ROWS` rows, no compiled kernel loaded
    yet in this process, a value of ``x`` not finite, or arrays of other kinds than
    SciPy's product takes."""
    m = st.matrix
    if (m.shape[0] < COMPILED_CHECK_MIN_ROWS or not kernel_loader.compiled_paid()
            or x.dtype != np.float64 or x.ndim != 1 or m.data.dtype != np.float64
            or m.indices.dtype not in (np.int32, np.int64)
            or not bool(np.isfinite(x).all())):
        return None
    groups = np.asarray(st.groups, dtype=np.int64)
    nature = (np.zeros(0, dtype=np.int64) if st.nature is None else
              np.asarray(st.nature, dtype=np.int64))
    return groups, nature


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
    got = _checked_arrays(st, x)
    if got is None:
        return None
    groups, nature = got
    ends = groups[[0, -1]] if st.nature is None else nature[groups[[0, -1]]]
    if states is None and (int(ends[0]) != 0 or int(ends[1]) != m.shape[0]):
        return None  # (the rows are not the states' choices one after the other)
    try:
        from mitld_lp.solvers.certify_kernels import bellman_rows
    except ImportError:  # pragma: no cover - numba is a dependency of the solvers
        return None
    args = (m.indptr, m.indices, m.data, np.ascontiguousarray(x), rnd.count, rnd.slack_of,
            rnd.high_of if upper else rnd.low_of, np.ascontiguousarray(free, dtype=bool),
            bool(upper))
    if states is None:
        # every state, :data:`CHECK_BATCH` at a time into its slice of the rows (a
        # state's rows follow the previous state's, from row 0): not an int64 index a
        # state beside the candidate (QVBS csma 4-2: 4.4 bytes a transition at the
        # certificate's traced peak); the same verdicts, row by row
        ok = np.empty(m.shape[0], dtype=bool)

        def row(s: int) -> int:  # state ``s``'s first row
            return int(groups[s] if st.nature is None else nature[groups[s]])

        for a in range(0, st.n_states, CHECK_BATCH):
            z = min(a + CHECK_BATCH, st.n_states)
            bellman_rows(np.arange(a, z, dtype=np.int64), groups, nature, *args,
                         ok[row(a):row(z)])
        return ok
    states = np.asarray(states, dtype=np.int64)
    first = groups[states] if st.nature is None else nature[groups[states]]
    last = groups[states + 1] if st.nature is None else nature[groups[states + 1]]
    ok = np.empty(int(np.sum(last - first)), dtype=bool)
    del first, last
    bellman_rows(states, groups, nature, *args, ok)
    return ok


def compiled_needs(st: Any, rnd: Rounding, x: np.ndarray, states: np.ndarray,
                    upper: bool) -> np.ndarray | None:
    """:func:`~mitld_lp.solvers.certify_repair._needed` by one compiled call
    (:func:`~mitld_lp.solvers.certify_repair_kernels.state_needs`: the same operations
    on the same operands, so the same values), read from the matrix in place with no rows or
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
        from mitld_lp.solvers.certify_repair_kernels import state_needs
    except ImportError:  # pragma: no cover - numba is a dependency of the solvers
        return None
    nature = (np.zeros(0, dtype=np.int64) if st.nature is None else
              np.asarray(st.nature, dtype=np.int64))
    out = np.empty(states.size)
    state_needs(states, groups, nature, m.indptr, m.indices, m.data,
                np.ascontiguousarray(x), rnd.count, rnd.slack_of,
                rnd.high_of if upper else rnd.low_of, bool(upper), out, False)
    return out


def compiled_failing(st: Any, rnd: Rounding, x: np.ndarray, free: np.ndarray,
                     states: np.ndarray | None = None, upper: bool = True,
                     ) -> np.ndarray | None:
    """The pre- (``upper``) or sub-fixed point Bellman check's failing states (a mask:
    those of ``states``, every state where None, that are not ``free``) by the repair's
    kernel (:func:`~mitld_lp.solvers.certify_repair_kernels.state_needs` asked for
    verdicts: the comparisons of :func:`~mitld_lp.solvers.certify_kernels.bellman_rows`
    on the same operands, a state at a time), so that a certificate links one kernel,
    not the check's beside the repair's, and no verdict a row is held and reduced over
    the choices (QVBS csma 4-2's lower bound: 658,129 rows).  None where :func:`compiled_checks`
    would not run, where a state has no choice or a choice no row, or (every state)
    where the rows are not the states' choices one after the other (the check's
    segmented reductions read other rows there)."""
    m = st.matrix
    got = _checked_arrays(st, x)
    if got is None:
        return None
    groups, nature = got
    if not bool(np.all(groups[1:] > groups[:-1])) or (
            st.nature is not None and not bool(np.all(nature[1:] > nature[:-1]))):
        return None
    ends = groups[[0, -1]] if st.nature is None else nature[groups[[0, -1]]]
    if int(ends[0]) != 0 or int(ends[1]) != m.shape[0]:
        return None
    try:
        from mitld_lp.solvers.certify_repair_kernels import state_needs
    except ImportError:  # pragma: no cover - numba is a dependency of the solvers
        return None
    free = np.asarray(free, dtype=bool)
    ask = (np.flatnonzero(~free) if states is None else
           np.asarray(states, dtype=np.int64)[~free[states]])
    failing = np.zeros(st.n_states, dtype=bool)
    if ask.size:
        ask = ask.astype(np.int64, copy=False)
        out = np.empty(ask.size)
        state_needs(ask, groups, nature, m.indptr, m.indices, m.data,
                    np.ascontiguousarray(x), rnd.count, rnd.slack_of,
                    rnd.high_of if upper else rnd.low_of, bool(upper), out, True)
        failing[ask] = out > 0
    return failing


def compiled_chain_sets(m: Any, states: np.ndarray, rows: np.ndarray, target: np.ndarray,
                        ) -> tuple[np.ndarray, np.ndarray] | None:
    """The ``never`` and ``sure`` sets of a policy's chain
    (:func:`~mitld_lp.solvers.certify_chain.chain`: its edges the positive entries of
    row ``rows[i]`` out of state ``states[i]``) by one compiled call
    (:func:`~mitld_lp.solvers.certify_kernels.chain_sets`: the same sets as the
    reversal and the two searches of :class:`~mitld_lp.solvers.reach.Reversed`); None
    where those run instead: fewer than :data:`COMPILED_CHECK_MIN_ROWS` acting states,
    no compiled kernel loaded yet in this process, numba not installed, or arrays of
    other kinds than SciPy's product takes, or more states or entries than an int32
    holds."""
    n = int(target.shape[0])
    if (states.size < COMPILED_CHECK_MIN_ROWS or not kernel_loader.compiled_paid()
            or m.data.dtype != np.float64 or max(n, m.nnz) >= 2**31 - 1
            or m.indices.dtype not in (np.int32, np.int64)):
        return None
    try:
        from mitld_lp.solvers.certify_kernels import chain_sets
    except ImportError:  # pragma: no cover - numba is a dependency of the solvers
        return None
    never, sure = np.empty(n, dtype=bool), np.empty(n, dtype=bool)
    # (the target copied: a writable array whatever the caller's, one signature of the
    # kernel and so one cache file, not a compile for a read-only one)
    chain_sets(np.asarray(states, dtype=np.int64), np.asarray(rows, dtype=np.int64),
               m.indptr, m.indices, m.data, np.array(target, dtype=bool), never, sure)
    return never, sure


def compiled_chain_parts(m: Any, states: np.ndarray, rows: np.ndarray, target: np.ndarray,
                         ) -> tuple[np.ndarray, ...] | None:
    """:func:`compiled_chain_sets` and the solved states' chain in the same call
    (:func:`~mitld_lp.solvers.certify_kernels.chain_parts`): ``(never, sure, idx, b,
    vals, cols, ptr)``, the arrays :func:`~mitld_lp.solvers.certify_chain.chain` gathers
    with NumPy (the same values, in the same order and index types: int32, as its
    ``index`` is for fewer states than an int32 holds).  None where
    :func:`compiled_chain_sets` would not run, or where ``states`` is not increasing
    (the NumPy code then runs)."""
    n = int(target.shape[0])
    if (states.size < COMPILED_CHECK_MIN_ROWS or not kernel_loader.compiled_paid()
            or m.data.dtype != np.float64 or max(n, m.nnz) >= 2**31 - 1
            or m.indices.dtype not in (np.int32, np.int64)
            or not bool(np.all(states[1:] > states[:-1]))):
        return None
    try:
        from mitld_lp.solvers.certify_kernels import chain_parts
    except ImportError:  # pragma: no cover - numba is a dependency of the solvers
        return None
    never, sure = np.empty(n, dtype=bool), np.empty(n, dtype=bool)
    # (the target copied, as for :func:`compiled_chain_sets`: one signature)
    got = chain_parts(np.asarray(states, dtype=np.int64), np.asarray(rows, dtype=np.int64),
                      m.indptr, m.indices, m.data, np.array(target, dtype=bool), never, sure)
    return (never, sure, *got)


CYCLING_MIN_STATES = 30_000
"""The fewest states a minimum's end-component test asks about
(:func:`compiled_cycling`) whose choices are read by the compiled kernel.  Set when a
kernel's first call could compile it (120,000 then); since ``mitld-lp warm`` compiles
it, its first call in a process is a link from the loader's cache, measured warm
(cert-84, the least of 7, CPU): QVBS firewire_dl 3-600 (93,996 states asked) 0.7 ms
compiled, 2.2 ms on the process's first call, against 5.0 ms of NumPy reads; csma 4-2
(232,810) 2.8 ms against 12.4.  The NumPy reads cost some 50 ns a state asked, the
first call's link about 1.5 ms: even then the kernel wins from about 30,000."""


def compiled_cycling(m: Any, groups: np.ndarray, comp: np.ndarray, left: np.ndarray,
                     ) -> np.ndarray | None:
    """:func:`~mitld_lp.solvers.certify_chain.cycling_among` by one compiled call
    (:func:`~mitld_lp.solvers.certify_kernels.cycling`: the same set, read from the
    matrix in place, nothing gathered); None where the NumPy reads run instead: fewer
    than :data:`CYCLING_MIN_STATES` states asked about, no compiled kernel loaded yet in
    this process, numba not installed, arrays of other kinds than SciPy's product takes,
    or a component number that is negative or not below the count of states."""
    n = int(left.shape[0])
    if (n < COMPILED_CHECK_MIN_ROWS or not kernel_loader.compiled_paid()
            or int(np.count_nonzero(left)) < CYCLING_MIN_STATES
            or m.indices.dtype not in (np.int32, np.int64)
            or m.indptr.dtype != m.indices.dtype or comp.shape[0] != n):
        return None
    try:
        from mitld_lp.solvers.certify_kernels import cycling
    except ImportError:  # pragma: no cover - numba is a dependency of the solvers
        return None
    out = np.zeros(n, dtype=bool)
    # (the inputs passed as read-only views: one signature of the kernel, and so one
    # cache file, whether the caller's arrays are writable or not)
    # (the components in their own index type where it is one: a product's are int32,
    # and a copy in int64 was a pass over the states of its own)
    comp = np.asarray(comp)
    if comp.dtype not in (np.int32, np.int64):
        comp = comp.astype(np.int64)
    done = cycling(*map(_read_only, (np.asarray(groups, dtype=np.int64), m.indptr,
                                     m.indices, comp, np.asarray(left, dtype=bool))), out)
    return out if done else None


ROUNDS_KERNEL = ("mitld_lp.solvers.certify_repair_kernels", "level_rounds")
"""The repair's rounds on a large level (:func:`compiled_rounds`), asked for its cache
file once a process (:func:`rounds_cached`)."""

_ROUNDS_WARM: list[bool] = []  # whether ROUNDS_KERNEL has a cache file, once a process


def rounds_cached() -> bool:
    """Whether the kernel loader would link :data:`ROUNDS_KERNEL` from its cache
    (:func:`~mitld_lp.util.kernel_loader.module_cached`), looked up once a process: a
    cold cache never makes a repair pay numba's compile."""
    if not _ROUNDS_WARM:
        _ROUNDS_WARM.append(kernel_loader.module_cached(*ROUNDS_KERNEL))
    return _ROUNDS_WARM[0]


def compiled_rounds(st: Any, rnd: Rounding, x: np.ndarray, mine: np.ndarray,
                    todo: np.ndarray, upper: bool, readers: tuple[np.ndarray, np.ndarray],
                    moved: np.ndarray, rounds: int, at: np.ndarray | None = None,
                    finite: bool = False) -> tuple[int, bool] | None:
    """The repair's rounds on the level ``mine`` from the states to do ``todo`` (a flag
    a state of ``mine``), in one compiled call
    (:func:`~mitld_lp.solvers.certify_repair_kernels.level_rounds`: the rounds of
    :meth:`~mitld_lp.solvers.certify_repair.Repair.run` on a large level, the same
    needs, moves and readers, so the same bounds in ``x``, flags in ``moved`` and
    count): ``(moves, settled)``; None where the NumPy rounds run instead: the kernel's
    load not paid or its cache file not there, arrays of other kinds than the kernel
    takes, a value of ``x`` not finite, or a state of ``mine`` without a choice or a
    choice without a row (:func:`compiled_needs`' refusals).  ``at``: a scratch int64
    a state of the model, -1 everywhere, left so (the kernel's map of the level's
    states, not made a call: a repair's many large levels each wrote one of the
    model's size, QVBS csma 3-4 all_before_max's 1,458,849 states 35 times); None:
    made here.  ``finite``: the caller knows ``x`` finite (the repair's moves keep it
    so), not checked again a call."""
    m = st.matrix
    col_ptr, col_state = readers
    if (not kernel_loader.compiled_paid() or not rounds_cached()
            or x.dtype != np.float64 or x.ndim != 1 or not x.flags.c_contiguous
            or not x.flags.writeable or m.data.dtype != np.float64
            or m.indices.dtype not in (np.int32, np.int64)
            or col_ptr.dtype not in (np.int32, np.int64)
            or col_state.dtype not in (np.int32, np.int64)
            or moved.dtype != np.bool_ or mine.size == 0):
        return None
    groups = np.asarray(st.groups, dtype=np.int64)
    mine = np.asarray(mine, dtype=np.int64)
    if not bool(np.all(groups[mine + 1] > groups[mine])) or (
            st.nature is not None and not bool(np.all(np.diff(st.nature) > 0))):
        return None
    if not finite and not bool(np.isfinite(x).all()):
        return None
    if at is None:
        at = np.full(x.shape[0], -1, dtype=np.int64)
    elif at.dtype != np.int64 or at.shape != x.shape or not at.flags.c_contiguous:
        raise ValueError("compiled_rounds: at must be an int64 scratch of a value a state")
    try:
        from mitld_lp.solvers.certify_repair_kernels import level_rounds
    except ImportError:  # pragma: no cover - numba is a dependency of the solvers
        return None
    nature = (np.zeros(0, dtype=np.int64) if st.nature is None else
              np.asarray(st.nature, dtype=np.int64))
    out = np.zeros(2, dtype=np.int64)
    # the arrays it only reads passed as read-only views (no copy): one signature of
    # the kernel, and so one cache file, whether the caller's are writable or not (a
    # product's are read-only, a test's not: else a warm cache of the one would still
    # make the other compile)
    level_rounds(*map(_read_only, (mine,)), np.array(todo, dtype=bool),
                 *map(_read_only, (groups, nature, m.indptr, m.indices, m.data)), x,
                 *map(_read_only, (rnd.count, rnd.slack_of,
                                   rnd.high_of if upper else rnd.low_of)),
                 bool(upper), *map(_read_only, (col_ptr, col_state)), int(rounds), moved,
                 out, at)
    return int(out[0]), bool(out[1])


def _read_only(a: np.ndarray) -> np.ndarray:
    """``a`` as a read-only view (C-contiguous: a copy only where it is not)."""
    view = np.ascontiguousarray(a).view()
    view.flags.writeable = False
    return view


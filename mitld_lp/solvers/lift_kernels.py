"""A minimum's lifted policy on its removed prob-0 states in one compiled pass (numba,
through :mod:`mitld_lp.util.kernel_loader`; imported only by
:func:`mitld_lp.solvers.quotient.staying_choices`, once the compiled kernels' load is
paid and this kernel's machine code is cached: ``mitld-lp warm`` compiles it).

Per state of ``states``: its first choice none of whose stored entries of positive
probability leaves ``inside`` (a stored zero is no edge), else its first choice -- what
:func:`~mitld_lp.solvers.rows.first_choice_without` finds with NumPy a chunk of entries
at a time, here a state at a time, its rows read until the first choice that stays (on
QVBS csma 4-2, 28,447 prob-0 states with a second choice).  The answer is the same
integer either way.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mitld_lp.util import kernel_loader

numba = kernel_loader.lazy_numba(globals())

__all__ = ["first_staying", "lift_states", "warm_up"]


@numba.njit(cache=True, nogil=True)
def first_staying_kernel(groups, indptr, indices, data, inside,
                         states):  # pragma: no cover - compiled
    """Per state of ``states``, int64: its first choice (rows ``groups[s]`` to
    ``groups[s + 1] - 1`` of the CSR arrays) with no entry of positive probability
    outside ``inside``, else its first choice."""
    out = np.empty(states.shape[0], dtype=np.int64)
    for k in range(states.shape[0]):
        out[k] = _first_stay(groups, indptr, indices, data, inside, states[k])
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def _first_stay(groups, indptr, indices, data, inside, s):  # pragma: no cover - compiled
    """State ``s``'s first choice with no entry of positive probability outside
    ``inside``, else its first choice."""
    for c in range(groups[s], groups[s + 1]):
        stays = True
        for e in range(indptr[c], indptr[c + 1]):
            if data[e] > 0.0 and not inside[indices[e]]:
                stays = False
                break
        if stays:
            return c
    return groups[s]


@numba.njit(cache=True, nogil=True)
def lift_states_kernel(groups, indptr, indices, data, zero, search, state_map, chosen, ends,
                       policy):  # pragma: no cover - compiled
    """:func:`~mitld_lp.solvers.quotient.lift_policy` where no end component is
    collapsed, a state at a time into ``policy`` (int64): a state of the quotient
    (``state_map >= 0``) the product choice of its chosen reduced choice
    (``chosen[state_map[s]]``); else ``-1`` on a target or absorbing state (``ends``);
    else, with ``search``, on a state of ``zero`` with several choices its first
    choice that stays in ``zero`` (:func:`first_staying_kernel`'s); else its first
    choice."""
    n = groups.shape[0] - 1
    for s in range(n):
        r = state_map[s]
        if r >= 0:
            policy[s] = chosen[r]
            continue
        if ends[s]:
            policy[s] = -1
            continue
        if search and zero[s] and groups[s + 1] - groups[s] > 1:
            policy[s] = _first_stay(groups, indptr, indices, data, zero, s)
        else:
            policy[s] = groups[s]


def _fixed(a: Any, dtype: Any = None) -> np.ndarray:
    """``a`` as a read-only view (a copy only where ``dtype`` differs): every call
    then has one kind of argument per dtype, so the signatures ``warm`` compiles are
    the ones a product's arrays give, whether they came writable or not."""
    out = np.asarray(a) if dtype is None else np.asarray(a, dtype=dtype)
    out = out.view()
    out.flags.writeable = False
    return out


def first_staying(groups: np.ndarray, matrix: Any, inside: np.ndarray,
                  states: np.ndarray) -> np.ndarray:
    """:func:`first_staying_kernel` on a CSR ``matrix`` (rows: choices; its index arrays
    as they are, int32 or int64), the states' ``groups`` as int64, ``inside`` as bool,
    ``states`` as int64."""
    indptr, indices = _fixed(matrix.indptr), _fixed(matrix.indices)
    if indices.dtype != indptr.dtype:  # one signature per index width
        indptr, indices = _fixed(indptr, np.int64), _fixed(indices, np.int64)
    return first_staying_kernel(_fixed(groups, np.int64), indptr, indices,
                                _fixed(matrix.data, np.float64), _fixed(inside, bool),
                                _fixed(states, np.int64))


def lift_states(groups: np.ndarray, matrix: Any, zero: np.ndarray, search: bool,
                state_map: np.ndarray, chosen: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """:func:`lift_states_kernel`'s policy (``(n,)`` int64), its arguments read-only views
    in the types a solve passes: ``groups`` int64, the matrix's index arrays as
    :func:`first_staying` takes them, ``state_map`` and ``chosen`` as they come (the
    caller takes this route where both are int32), the masks bool."""
    indptr, indices = _fixed(matrix.indptr), _fixed(matrix.indices)
    if indices.dtype != indptr.dtype:  # one signature per index width
        indptr, indices = _fixed(indptr, np.int64), _fixed(indices, np.int64)
    policy = np.empty(groups.shape[0] - 1, dtype=np.int64)
    lift_states_kernel(_fixed(groups, np.int64), indptr, indices, _fixed(matrix.data, np.float64),
                       _fixed(zero, bool), bool(search), _fixed(state_map), _fixed(chosen),
                       _fixed(ends, bool), policy)
    return policy


def warm_up() -> None:
    """Compile (or load) the kernel for both index widths a product's matrix has, on a
    two-state model: ``mitld-lp warm``'s part for the lifted policy."""
    import scipy.sparse as sp

    groups = np.array([0, 2, 3], dtype=np.int64)
    for index in (np.int32, np.int64):
        m = sp.csr_array((np.array([1.0, 0.5, 0.5, 1.0]),
                          np.array([1, 0, 1, 1], dtype=index),
                          np.array([0, 1, 3, 4], dtype=index)), shape=(3, 2))
        got = first_staying(groups, m, np.array([True, False]), np.array([0]))
        assert got.tolist() == [0], got  # both choices leave to state 1: the first
    m = sp.csr_array((np.array([1.0, 0.5, 0.5, 1.0]), np.array([1, 0, 1, 1], dtype=np.int32),
                      np.array([0, 1, 3, 4], dtype=np.int32)), shape=(3, 2))
    got = lift_states(groups, m, np.array([True, False]), True,
                      np.array([-1, 0], dtype=np.int32), np.array([2], dtype=np.int32),
                      np.array([False, False]))
    assert got.tolist() == [0, 2], got

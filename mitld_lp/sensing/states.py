"""The records of an information-state product's states, made on demand from the build's
integer columns (:class:`InfoStates`, the ``states`` of the MDP that
:mod:`mitld_lp.sensing.frontier` builds).

Making an :class:`~mitld_lp.sensing.info.InfoState` (a tuple of hypotheses, a tuple of
weights, two frozensets) for each of a product's hundreds of thousands of states took a
tenth of the build and most callers never look at them: the solvers read the matrix, the
controller its moves (:class:`~mitld_lp.sensing.moves.Moves`) and which states are
absorbing records (:meth:`InfoStates.absorbing`).  Item ``i`` is made when asked for,
the same record the build made before (equal, with the same hash)."""

from __future__ import annotations

from collections.abc import Hashable, Iterator, Mapping, Sequence
from typing import Any, overload

import numpy as np

from mitld_lp.product import Absorbing
from mitld_lp.sensing.info import InfoState
from mitld_lp.sensing.moves import PackedRuns

__all__ = ["InfoStates"]


class InfoStates(Sequence[Hashable]):
    """The product's states: an :class:`InfoState` for each information state, its
    record (an :class:`Absorbing` member or an ``ends`` record) for the others.

    ``cols``: per state its world index, clock, reported set's and pending set's masks,
    first hypothesis and number of hypotheses (the build's :class:`Columns`);
    ``codes``, ``weights``: every state's hypotheses (``times index * nq + automaton
    state``) and posteriors; ``times``, ``worlds``, ``s_sets``, ``u_sets``: the build's
    tables the indices read; ``records``: the absorbing records by state.

    The three arrays are kept packed (:class:`~mitld_lp.sensing.moves.PackedRuns`, zlib
    level 1) until a record is first asked for (:meth:`columns`): the solvers read the
    matrix only, and the product's records are asked for after the solve, which the
    arrays would otherwise sit through (issue 45's sensed case: 3.9 bytes a transition
    packed into 0.4, some 13 ms CPU; the posteriors repeat)."""

    __slots__ = ("_n", "_packed", "_arrays", "_nq", "_times", "_worlds", "_s_sets",
                 "_u_sets", "_records")

    def __init__(self, cols: np.ndarray, codes: np.ndarray, weights: np.ndarray, nq: int,
                 times: Sequence[tuple[int, ...]], worlds: Sequence[Hashable],
                 s_sets: Sequence[frozenset[str]], u_sets: Sequence[frozenset[str]],
                 records: Mapping[int, Hashable]) -> None:
        self._n = int(cols.shape[1])
        self._packed: PackedRuns | None = PackedRuns([(cols.reshape(-1), codes, weights)])
        self._arrays: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._nq, self._times, self._worlds = nq, times, worlds
        self._s_sets, self._u_sets = s_sets, u_sets
        self._records = dict(records)

    def __len__(self) -> int:
        return self._n

    def columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(cols, codes, weights)`` (class docs), unpacked at the first call and kept
        from then on (read-only, the bits as built)."""
        if self._arrays is None:
            assert self._packed is not None
            ((flat, codes, weights),) = self._packed.unpack()
            self._arrays = (flat.reshape(-1, self._n) if self._n else
                            np.zeros((6, 0), flat.dtype), codes, weights)
            self._packed = None
        return self._arrays

    def _make(self, i: int) -> Hashable:
        record = self._records.get(i)
        if record is not None:
            return record
        cols, codes, weights = self.columns()
        w, t, r, p, h, n = cols[:, i].tolist()
        times, nq = self._times, self._nq
        return InfoState(self._worlds[w], t, self._s_sets[r], self._u_sets[p],
                         tuple((times[c // nq], c % nq) for c in codes[h:h + n].tolist()),
                         tuple(weights[h:h + n].tolist()))

    @overload
    def __getitem__(self, i: int) -> Hashable: ...
    @overload
    def __getitem__(self, i: slice) -> tuple[Hashable, ...]: ...
    def __getitem__(self, i: int | slice) -> Hashable | tuple[Hashable, ...]:
        n = len(self)
        if isinstance(i, slice):
            return tuple(self._make(k) for k in range(*i.indices(n)))
        k = int(i)
        if not -n <= k < n:
            raise IndexError(f"information state {i} out of range (0 .. {n - 1})")
        return self._make(k + n if k < 0 else k)

    def __iter__(self) -> Iterator[Hashable]:
        return (self._make(k) for k in range(len(self)))

    def __eq__(self, other: object) -> bool:
        if isinstance(other, InfoStates | tuple | list):
            return len(self) == len(other) and all(
                a == b for a, b in zip(self, other, strict=True))
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"InfoStates(<{len(self)} states>)"

    def absorbing(self) -> np.ndarray:
        """``(n,)`` bool: the states that are :class:`Absorbing` records (no object made
        for the others)."""
        out = np.zeros(len(self), bool)
        at = [i for i, r in self._records.items() if isinstance(r, Absorbing)]
        out[np.asarray(at, np.int64)] = True
        return out

    def __reduce__(self) -> tuple[Any, ...]:
        return (InfoStates, (*self.columns(), self._nq,
                             list(self._times), list(self._worlds), list(self._s_sets),
                             list(self._u_sets), self._records))

"""Export the occupancy LP (MPS / CPLEX-LP, via HiGHS), whose optimum is the value, and
the MDP (Storm's DRN format).

Both writers follow the package's one rule for output files (:mod:`mitld_lp.files.write`):
they refuse to overwrite an existing file unless ``overwrite=True``, and write to a
temporary file renamed over the target once complete, so an interrupted or failed write
leaves the target as it was.

LP names: column ``y<c>`` is the occupancy of original choice ``c``; row ``s<i>`` is the
flow constraint of original state ``i`` (a maybe state outside any MEC), row ``mec<k>``
the one of collapsed MEC ``k`` (see :func:`mitld_lp.solvers.quotient.maximal_end_components`).
"""

from __future__ import annotations

import importlib
import logging
import os
import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.files import write as files
from mitld_lp.mdp import MDP, as_state_mask
from mitld_lp.solvers.lp import occupancy_lp
from mitld_lp.util.quiet import native_quiet

__all__ = ["drn_text", "write_lp", "write_drn", "LP_SUFFIXES", "DRN_SUFFIXES"]

logger = logging.getLogger(__name__)

LP_SUFFIXES = (".mps", ".lp")
DRN_SUFFIXES = (".drn",)


def write_lp(
    mdp: MDP,
    target: np.ndarray,
    path: str | os.PathLike[str],
    *,
    overwrite: bool = False,
) -> Path:
    """Write to ``path`` the LP whose optimum is the value: the maximal probability of
    reaching ``target`` from the initial state.

    The format follows the suffix: ``.mps`` (free MPS) or ``.lp`` (CPLEX LP).  The LP is
    the occupancy LP that :func:`mitld_lp.solvers.solve_lp` solves (as one LP), with
    start weight 1 on the initial state: over the reduced states (target and prob-0
    states removed, end components collapsed; see
    :func:`mitld_lp.solvers.quotient.reduce`), maximise ``sum_c y(c) P(c, target)``
    subject to ``sum_{c of s} y(c) - sum_c' y(c') P(c', s) = [s = initial]`` and
    ``y >= 0``.  Where graph analysis already decides the initial state (a target state:
    1; a prob-0 state: 0), the LP is the one row ``s<initial>: sum_{c of initial} y(c)
    = 1`` with that value as every column's objective coefficient.  Either way any solver
    that reads the file finds the value as its optimal objective.  The model goes
    through HiGHS (``Highs.passModel`` then ``Highs.writeModel``); the command line's
    ``export --lp`` writes this same LP.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is false.
        ValueError: a path :func:`mitld_lp.files.write.writable_path` refuses (a suffix other
            than ``.mps``/``.lp``).
        OSError: HiGHS failed to write the file.
    """
    p = files.writable_path(path, overwrite=overwrite, suffixes=LP_SUFFIXES)
    lp = occupancy_lp(mdp, target)
    q = lp.quotient
    if q.initial >= 0:
        a = sp.csc_array(lp.a_eq)
        b, objective = lp.b_eq, lp.objective
        columns = q.choice_origin
        plain = np.flatnonzero((q.state_map >= 0) & (q.mecs.mec_of < 0))
        rows = [f"s{i}" for i in plain.tolist()] + [f"mec{k}" for k in range(q.mecs.n_mecs)]
    else:  # decided by graph analysis: one row, the initial state's choices
        columns = np.arange(mdp.row_groups[mdp.initial], mdp.row_groups[mdp.initial + 1])
        a = sp.csc_array(np.ones((1, columns.size)))
        b, objective = np.ones(1), np.full(columns.size, q.initial_value)
        rows = [f"s{mdp.initial}"]
    n_rows, n_cols = len(rows), columns.size
    highspy: Any = importlib.import_module("highspy")
    model = highspy.HighsLp()
    model.num_col_ = n_cols
    model.num_row_ = n_rows
    model.sense_ = highspy.ObjSense.kMaximize
    model.col_cost_ = np.asarray(objective, dtype=np.float64)
    model.col_lower_ = np.zeros(n_cols)
    model.col_upper_ = np.full(n_cols, highspy.kHighsInf)
    model.row_lower_ = np.asarray(b, dtype=np.float64)
    model.row_upper_ = np.asarray(b, dtype=np.float64)
    model.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    model.a_matrix_.num_col_ = n_cols
    model.a_matrix_.num_row_ = n_rows
    model.a_matrix_.start_ = np.asarray(a.indptr, dtype=np.int32)
    model.a_matrix_.index_ = np.asarray(a.indices, dtype=np.int32)
    model.a_matrix_.value_ = np.asarray(a.data, dtype=np.float64)
    model.col_names_ = [f"y{c}" for c in columns.tolist()]
    model.row_names_ = rows
    with native_quiet("highs"):  # its banner, printed before output_flag can be set
        highs = highspy.Highs()
        highs.setOptionValue("output_flag", False)
        status = highs.passModel(model)
    if status == highspy.HighsStatus.kError:
        raise OSError(f"{p}: HiGHS rejected the model ({status})")
    with files.replacing_path(p) as scratch, native_quiet("highs"):
        status = highs.writeModel(str(scratch))
        if status == highspy.HighsStatus.kError or not scratch.exists():
            raise OSError(f"{p}: HiGHS failed to write the model ({status})")
    logger.info("wrote LP (%d rows, %d columns) to %s", n_rows, n_cols, p)
    return p


_TOKEN = re.compile(r"\s+")

_DRN_CHUNK = 50_000
"""States whose lines :func:`drn_text` formats at a time."""


def _drn_action(name: str) -> str:
    return _TOKEN.sub("_", name.strip()) or "_"


def _valuation(record: object) -> str:
    """A state's valuation for the DRN comment line: ``var=value`` joined by `` & ``."""
    game = getattr(record, "game", None)
    if game is None or not hasattr(record, "pending"):
        return str(record) if isinstance(record, str) else f"state={_compact(record)}"
    pending = ",".join(sorted(record.pending))  # type: ignore[attr-defined]
    return (f"game={_compact(game)} & q={record.automaton} & "  # type: ignore[attr-defined]
            f"pending={{{pending}}} & clock={record.clock}")  # type: ignore[attr-defined]


def _compact(value: object) -> str:
    """``value`` on one line without spaces (a DRN line is split on whitespace)."""
    return "".join(str(value).split())


class _Valuations:
    """:func:`_valuation` with the parts that many states share (a game state, a set of
    pending events) formatted once; ``world``: how a game state is written (default
    ``game=(...)``; a PRISM world's caller gives its variables, ``x=1 & y=2``)."""

    def __init__(self, world: Callable[[object], str] | None = None) -> None:
        self.games: dict[object, str] = {}
        self.pending: dict[object, str] = {}
        self.world = world or (lambda g: f"game={_compact(g)}")

    def __call__(self, record: object) -> str:
        game = getattr(record, "game", None)
        if game is None or not hasattr(record, "pending"):
            return _valuation(record)
        g = self.games.get(game)
        if g is None:
            g = self.games[game] = self.world(game)
        pend = record.pending  # type: ignore[attr-defined]
        p = self.pending.get(pend)
        if p is None:
            p = self.pending[pend] = ",".join(sorted(pend))
        return (f"{g} & q={record.automaton} & "  # type: ignore[attr-defined]
                f"pending={{{p}}} & clock={record.clock}")  # type: ignore[attr-defined]


def _strings(values: np.ndarray, fmt: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(table, index)``: ``fmt`` of each distinct entry of ``values`` once, as an object
    array, and where each entry's string is in it."""
    distinct, index = np.unique(values, return_inverse=True)
    table = np.empty(distinct.shape[0], dtype=object)
    table[:] = [fmt(v) for v in distinct.tolist()]
    return table, index


def _successors(cols: np.ndarray) -> np.ndarray:
    """``"\\t\\t{c} : "`` for each entry of ``cols`` (object array): the successors of a
    chunk lie in a narrow range of states, so a table over that range is made without
    sorting (a sort of the distinct ones if the range is wide)."""
    if cols.size == 0:
        return np.empty(0, dtype=object)
    low, high = int(cols.min()), int(cols.max())
    if high - low > cols.size:
        table, index = _strings(cols, lambda c: f"\t\t{c} : ")
        return table[index]
    table = np.empty(high - low + 1, dtype=object)
    table[:] = [f"\t\t{c} : " for c in range(low, high + 1)]
    return table[cols - low]


def drn_text(mdp: MDP, marks: list[tuple[str, np.ndarray]], *,
             valuations: bool = True,
             world: Callable[[object], str] | None = None) -> Iterator[str]:
    """The ``@model`` section of ``mdp``'s DRN text, a chunk of :data:`_DRN_CHUNK`
    states at a time (the text of a 1e6-state model never sits in memory whole).

    ``marks``: ``(label, state mask)`` in the order the labels are written after
    ``init``.  Vectorised: every distinct successor, probability, action and label set
    of a chunk is formatted once, and the chunk's lines are one ``join`` of those
    pieces put in place by array indexing; only the valuations are formatted state by
    state.  Successors are listed in increasing order, zero entries left out.
    """
    n = mdp.n_states
    matrix = mdp.matrix
    row_groups = np.asarray(mdp.row_groups, dtype=np.int64)
    actions = np.asarray(mdp.choice_actions, dtype=np.int64)
    action_lines = np.array([f"\taction {_drn_action(a)}\n" for a in mdp.action_names]
                            + ["\taction absorb\n"], dtype=object)
    codes = np.zeros(n, dtype=np.int64)
    codes[int(mdp.initial)] = 1
    for bit, (_, mask) in enumerate(marks, start=1):
        codes |= np.asarray(mask, dtype=np.int64) << bit
    valuation = _Valuations(world)
    for lo in range(0, n, _DRN_CHUNK):
        hi = min(n, lo + _DRN_CHUNK)
        c_lo, c_hi = int(row_groups[lo]), int(row_groups[hi])
        p_lo, p_hi = int(matrix.indptr[c_lo]), int(matrix.indptr[c_hi])
        rows = sp.csr_array((np.array(matrix.data[p_lo:p_hi]),
                             np.array(matrix.indices[p_lo:p_hi]),
                             np.asarray(matrix.indptr[c_lo:c_hi + 1], dtype=np.int64) - p_lo),
                            shape=(c_hi - c_lo, n))
        rows.sort_indices()
        keep = rows.data > 0
        cols, vals = rows.indices[keep], rows.data[keep]
        entry_row = np.repeat(np.arange(c_hi - c_lo), np.diff(rows.indptr))[keep]
        row_len = np.bincount(entry_row, minlength=c_hi - c_lo)
        # Places: per state its header, then per choice its action line and two pieces
        # (successor, probability) per entry.
        size = 1 + 2 * row_len
        before = np.concatenate([[0], np.cumsum(size)])  # pieces of earlier choices
        owner = np.repeat(np.arange(hi - lo), np.diff(row_groups[lo:hi + 1]))
        choice_at = owner + 1 + before[:-1]
        state_at = np.arange(hi - lo) + before[row_groups[lo:hi] - c_lo]
        first = np.concatenate([[0], np.cumsum(row_len)])
        entry_at = choice_at[entry_row] + 1 + 2 * (np.arange(cols.size) - first[entry_row])
        pieces = np.empty(hi - lo + c_hi - c_lo + 2 * cols.size, dtype=object)
        pieces[choice_at] = action_lines[actions[c_lo:c_hi]]
        pieces[entry_at] = _successors(cols)
        table, index = _strings(vals, lambda v: f"{v!r}\n")
        pieces[entry_at + 1] = table[index]
        labels = {code: "".join(" " + name for bit, name in enumerate(
            ["init", *(m for m, _ in marks)]) if code >> bit & 1)
                  for code in np.unique(codes[lo:hi]).tolist()}
        chunk_codes = codes[lo:hi].tolist()
        if valuations:
            records = mdp.states[lo:hi]
            heads = [f"state {s}{labels[code]}\n//[{valuation(rec)}]\n" for s, code, rec
                     in zip(range(lo, hi), chunk_codes, records, strict=True)]
        else:
            heads = [f"state {s}{labels[code]}\n" for s, code in
                     zip(range(lo, hi), chunk_codes, strict=True)]
        pieces[state_at] = heads
        yield "".join(pieces.tolist())


def write_drn(
    mdp: MDP,
    target: np.ndarray,
    path: str | os.PathLike[str],
    *,
    overwrite: bool = False,
    truncated_label: bool = True,
    valuations: bool = True,
    world: Callable[[object], str] | None = None,
) -> Path:
    """Write ``mdp`` in Storm's explicit DRN format (``@type: MDP``).

    State ``i`` of the file is state ``i`` of ``mdp``; its choices appear in row order
    with the action names of ``mdp.action_names`` (whitespace replaced by ``_``) or
    ``absorb`` as choice labels (Storm's DRN parser keeps them with
    ``build_choice_labeling``, so a scheduler Storm computes maps back action by
    action).  Labels: ``init``; ``target`` and ``accept`` on the states of ``target``
    (so ``Pmax=? [F "accept"]`` in Storm is the quantity :func:`solve_lp` computes; for
    a task with a safety part the caller passes the union of its accepting end
    components, :func:`mitld_lp.routes.acceptance.acceptance`);
    ``sink``; ``truncated`` (unless ``truncated_label=False``); when ``target`` is
    empty, one more state that no state reaches carries ``target`` and ``accept``, so
    that Storm knows them and answers 0.  With ``valuations``,
    each ``state`` line is followed by the state's valuation as Storm's own exporter
    writes it, a comment ``//[game=(1,2) & q=3 & pending={b1,b2} & clock=0]`` (the game
    state, the automaton state, the events still pending, the clock), or
    ``//[target]`` / ``//[sink]`` / ``//[truncated]`` for the absorbing states;
    ``world`` writes the game state in the world's own terms instead of ``game=...``
    (the command line gives a PRISM world's variables, ``x=2 & open=true``).
    Probabilities are written with Python's shortest round-trip ``repr``.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is false.
        ValueError: a path :func:`mitld_lp.files.write.writable_path` refuses.
    """
    target = as_state_mask(mdp, target, "target")
    p = files.writable_path(path, overwrite=overwrite, suffixes=DRN_SUFFIXES)
    n = mdp.n_states
    marks = [("target", target), ("accept", target),
             ("sink", np.asarray(mdp.sink, dtype=bool))]
    if truncated_label:
        marks.append(("truncated", np.asarray(mdp.truncated, dtype=bool)))
    # target and accept on no state (the value is 0) go on one more state that no state
    # reaches, so that Storm knows them (DRN declares labels only on states)
    unused = [] if target.any() else ["target", "accept"]
    header = [
        "// Exported by mitld_lp",
        "@type: MDP",
        "@parameters",
        "",
        "@reward_models",
        "",
        "@nr_states",
        str(n + bool(unused)),
        "@nr_choices",
        str(mdp.n_choices + bool(unused)),
        "@model",
    ]
    with files.replacing(p) as f:
        f.write("\n".join(header) + "\n")
        for text in drn_text(mdp, marks, valuations=valuations, world=world):
            f.write(text)
        if unused:
            f.write(f"state {n} {' '.join(unused)}\n\taction absorb\n\t\t{n} : 1.0\n")
    logger.info("wrote DRN (%d states, %d choices) to %s", n, mdp.n_choices, p)
    return p

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
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, overload

import numpy as np
import scipy.sparse as sp

from mitld_lp.files import drn
from mitld_lp.files import write as files
from mitld_lp.files.drn import DrnModel
from mitld_lp.mdp import MDP, as_state_mask
from mitld_lp.solvers.lp import occupancy_lp
from mitld_lp.util.quiet import native_quiet

__all__ = ["write_lp", "write_drn", "product_drn", "ProductValuations", "LP_SUFFIXES",
           "DRN_SUFFIXES"]

logger = logging.getLogger(__name__)

LP_SUFFIXES = (".mps", ".lp")
DRN_SUFFIXES = drn.SUFFIXES


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


def _compact(value: object) -> str:
    """``value`` on one line without spaces (a DRN line is split on whitespace)."""
    return "".join(str(value).split())


class ProductValuations(Sequence[str]):
    """The valuation of each state of a product MDP, formatted when asked (the file is
    written a chunk at a time): ``game=(1,2) & q=3 & pending={b1,b2} & clock=0`` (the
    game state, the automaton state, the events still pending, the clock), the record's
    text for an absorbing state (``target`` / ``sink`` / ``truncated``), else
    ``state=...``.  The parts that many states share (a game state, a set of pending
    events) are formatted once; ``world`` writes a game state in the world's own terms
    (a PRISM world's caller gives its variables, ``x=1 & y=2``)."""

    def __init__(self, states: Sequence[object],
                 world: Callable[[object], str] | None = None) -> None:
        self.states = states
        self.games: dict[object, str] = {}
        self.pending: dict[object, str] = {}
        self.world = world or (lambda g: f"game={_compact(g)}")

    def __len__(self) -> int:
        return len(self.states)

    @overload
    def __getitem__(self, index: int) -> str: ...

    @overload
    def __getitem__(self, index: slice) -> list[str]: ...

    def __getitem__(self, index: int | slice) -> str | list[str]:
        if isinstance(index, slice):
            return [self.text(record) for record in self.states[index]]
        return self.text(self.states[index])

    def text(self, record: object) -> str:
        game = getattr(record, "game", None)
        if game is None or not hasattr(record, "pending"):
            return str(record) if isinstance(record, str) else f"state={_compact(record)}"
        g = self.games.get(game)
        if g is None:
            g = self.games[game] = self.world(game)
        pend = record.pending  # type: ignore[attr-defined]
        p = self.pending.get(pend)
        if p is None:
            p = self.pending[pend] = ",".join(sorted(pend))
        return (f"{g} & q={record.automaton} & "  # type: ignore[attr-defined]
                f"pending={{{p}}} & clock={record.clock}")  # type: ignore[attr-defined]


def product_drn(mdp: MDP, target: np.ndarray, *, truncated_label: bool = True,
                valuations: bool = True,
                world: Callable[[object], str] | None = None) -> DrnModel:
    """What :func:`write_drn` writes: ``mdp`` with its labels, actions and valuations."""
    target = as_state_mask(mdp, target, "target")
    labels = [("target", target), ("accept", target), ("sink", np.asarray(mdp.sink, bool))]
    if truncated_label:
        labels.append(("truncated", np.asarray(mdp.truncated, dtype=bool)))
    return DrnModel(matrix=mdp.matrix, row_groups=mdp.row_groups, initial=int(mdp.initial),
                    labels=tuple(labels), declared=("target", "accept"),
                    action_names=mdp.action_names, choice_actions=mdp.choice_actions,
                    valuations=ProductValuations(mdp.states, world) if valuations else None,
                    comment="Exported by mitld_lp")


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
    """Write ``mdp`` in Storm's explicit DRN format (``@type: MDP``), through the one DRN
    writer (:mod:`mitld_lp.files.drn`).

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
    writes it, a comment ``//[game=(1,2) & q=3 & pending={b1,b2} & clock=0]``
    (:class:`ProductValuations`), or ``//[target]`` / ``//[sink]`` / ``//[truncated]``
    for the absorbing states; ``world`` writes the game state in the world's own terms
    instead of ``game=...`` (the command line gives a PRISM world's variables,
    ``x=2 & open=true``).  Probabilities are written with Python's shortest round-trip
    ``repr``.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is false.
        ValueError: a path :func:`mitld_lp.files.write.writable_path` refuses.
    """
    target = as_state_mask(mdp, target, "target")
    p = files.writable_path(path, overwrite=overwrite, suffixes=drn.SUFFIXES)
    return drn.write(product_drn(mdp, target, truncated_label=truncated_label,
                                 valuations=valuations, world=world), p, overwrite=overwrite)

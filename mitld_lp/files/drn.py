"""Storm's explicit DRN format: the one writer of every model the package exports (the
product MDP, the interval MDP, the merged model of a constrained synthesis, the
controlled chain).

Each export says what its file holds as a :class:`DrnModel`; :func:`write` writes it
through the package's one file writer (:mod:`mitld_lp.files.write`: the path checked,
a temporary file renamed into place), a chunk of :data:`CHUNK_STATES` states at a time
(:func:`drn_text`), so the text of a model of millions of states never sits in memory
whole.  The file, as Storm's DRN parser reads it::

    // a comment
    @type: MDP                      (or DTMC: one choice per state)
    @parameters
                                    (none: no parametric model is written)
    @reward_models
    steps cost                      (the reward models' names)
    @nr_states
    12
    @nr_choices
    30
    @model
    state 0 [0, 1.5] init target    (the state rewards, one per reward model, then labels)
    //[x=1 & q=0]                   (the state's valuation, a comment)
    \taction north [1, 0]           (the choice's label, then its rewards)
    \t\t3 : 0.25                    (a successor and its probability, or [lo, hi])

The rules, kept here once:

* State ``i`` of the file is state ``i`` of the model; its choices follow in row order.
* Labels: ``init`` on the initial state, then the model's labels in their order.  A
  *declared* label (the ones an export's documentation tells the user to check) that no
  state carries goes on one more state after the others, which no state reaches and
  which loops on itself: DRN declares a label only on a state, so without it Storm
  refuses a property that names the label, where the answer is 0.
* A choice is labelled by its action's name (whitespace replaced by ``_``; ``absorb``
  for :data:`~mitld_lp.mdp.ABSORB`), or, in a model without action names, by its index
  among its state's choices, as Storm's own exporter does.
* Successors are written in increasing order, entries of probability 0 (an interval's
  upper end 0) left out; probabilities with Python's shortest round-trip ``repr``, an
  interval model's as ``[lo, hi]`` (``stormpy.build_model_from_drn[stormpy.Interval]``).
* A reward model with state rewards writes them on every state line, one with choice
  rewards on every action line (``0`` for a reward model without that kind); an integer
  reward is written as an integer.
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import scipy.sparse as sp

from mitld_lp.files import write as files
from mitld_lp.mdp import MDPShape

__all__ = ["DrnModel", "Reward", "drn_text", "write", "SUFFIXES", "CHUNK_STATES",
           "action_token"]

logger = logging.getLogger(__name__)

SUFFIXES = (".drn",)

CHUNK_STATES = 50_000
"""States whose lines :func:`drn_text` formats at a time."""

_TOKEN = re.compile(r"\s+")
_NAME = re.compile(r'[^\s"\[\]]+')
"""A label or reward model's name: one token, which Storm's parser reads back whole."""


def action_token(name: str) -> str:
    """An action's name as a DRN choice label: one token (whitespace replaced by ``_``)."""
    return _TOKEN.sub("_", name.strip()) or "_"


@dataclass(frozen=True, slots=True, eq=False)
class Reward:
    """One reward model: ``state[s]`` earned in state ``s``, ``choice[c]`` on taking
    choice ``c`` (either may be None)."""

    name: str
    state: np.ndarray | None = None
    choice: np.ndarray | None = None


@dataclass(frozen=True, slots=True, eq=False, kw_only=True)
class DrnModel(MDPShape):
    """What a DRN file holds (module docstring).

    Attributes:
        matrix: ``(n_choices, n_states)`` CSR: the probabilities, or in an interval model
            the lower ends.
        row_groups: the choices of each state (:class:`~mitld_lp.mdp.MDPShape`).
        initial: the state labelled ``init``.
        kind: ``"MDP"`` or ``"DTMC"`` (one choice per state).
        labels: ``(name, (n_states,) bool mask)``, written after ``init`` in this order.
        declared: label names the file declares even when no state carries them.
        action_names, choice_actions: per choice its action, an index into
            ``action_names`` (``ABSORB`` for ``absorb``); None: the choice's index in
            its state.
        upper: per stored entry of ``matrix`` (in its order) the interval's upper end;
            None for point probabilities.
        valuations: per state the text of its valuation comment, or None.
        rewards: the reward models.
        comment: the file's first line, a comment (None: no comment).
    """

    matrix: sp.csr_array
    row_groups: np.ndarray
    initial: int
    kind: Literal["MDP", "DTMC"] = "MDP"
    labels: tuple[tuple[str, np.ndarray], ...] = ()
    declared: tuple[str, ...] = ()
    action_names: tuple[str, ...] | None = None
    choice_actions: np.ndarray | None = None
    upper: np.ndarray | None = None
    valuations: Sequence[str] | None = None
    rewards: tuple[Reward, ...] = ()
    comment: str | None = None

    def __post_init__(self) -> None:
        n, m = self.n_states, self.n_choices
        fault = _fault(self, n, m)
        if fault:
            raise ValueError(f"DRN model: {fault}")

    def successors(self, choice: int) -> np.ndarray:
        """The states ``choice`` may reach, increasing: in an interval model those whose
        interval's upper end is positive (its lower end may be 0)."""
        if self.upper is None:
            return MDPShape.successors(self, choice)
        lo, hi = int(self.matrix.indptr[choice]), int(self.matrix.indptr[choice + 1])
        return np.unique(self.matrix.indices[lo:hi][self.upper[lo:hi] > 0])

    def missing(self) -> tuple[str, ...]:
        """The declared labels no state carries (written on the declaring state)."""
        carried = {name for name, mask in self.labels if np.any(mask)}
        return tuple(name for name in self.declared if name not in carried)


def _fault(model: DrnModel, n: int, m: int) -> str | None:
    """What is wrong with ``model`` (``n`` states, ``m`` choices), or None."""
    if model.kind not in ("MDP", "DTMC"):
        return f"kind {model.kind!r} is neither MDP nor DTMC"
    if model.kind == "DTMC" and np.any(np.diff(model.row_groups) != 1):
        return "a DTMC has one choice per state"
    if model.matrix.shape != (m, n):
        return f"the matrix is {model.matrix.shape}, not ({m}, {n})"
    if not 0 <= model.initial < n:
        return f"initial state {model.initial} is not one of the {n} states"
    for name in [*(name for name, _ in model.labels), *model.declared,
                 *(r.name for r in model.rewards)]:
        if not _NAME.fullmatch(name):
            return f"{name!r} is not one token (label and reward model names)"
    for name, mask in model.labels:
        if np.shape(mask) != (n,):
            return f"label {name!r}: {np.shape(mask)} entries for {n} states"
    if (model.action_names is None) != (model.choice_actions is None):
        return "action_names and choice_actions go together"
    if model.choice_actions is not None and np.shape(model.choice_actions) != (m,):
        return f"{np.shape(model.choice_actions)} choice actions for {m} choices"
    if model.upper is not None and np.shape(model.upper) != model.matrix.data.shape:
        return "upper has not one entry per stored entry of the matrix"
    if model.valuations is not None and len(model.valuations) != n:
        return f"{len(model.valuations)} valuations for {n} states"
    for r in model.rewards:
        for what, values, size in (("state", r.state, n), ("choice", r.choice, m)):
            if values is None:
                continue
            if np.shape(values) != (size,):
                return f"reward {r.name!r}: {np.shape(values)} {what} rewards for {size}"
            if np.asarray(values).dtype.kind not in "iuf":
                return f"reward {r.name!r}: {what} rewards are not numbers"
    return None


def write(model: DrnModel, path: str | os.PathLike[str], *,
          overwrite: bool = False) -> Path:
    """Write ``model`` to ``path`` (``.drn``) under the package's rule for output files.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is false.
        ValueError: a path :func:`mitld_lp.files.write.writable_path` refuses.
    """
    p = files.writable_path(path, overwrite=overwrite, suffixes=SUFFIXES)
    with files.replacing(p) as f:
        for text in drn_text(model):
            f.write(text)
    logger.info("wrote DRN (%s, %d states, %d choices, %d transitions) to %s", model.kind,
                model.n_states, model.n_choices, model.n_transitions, p)
    return p


def drn_text(model: DrnModel) -> Iterator[str]:
    """The file's text (module docstring): the header, then the states a chunk of
    :data:`CHUNK_STATES` at a time, then the state declaring the missing labels.

    Vectorised: every distinct successor, probability, action and label set of a chunk
    is formatted once, and the chunk's lines are one ``join`` of those pieces put in
    place by array indexing; only the state lines are formatted one by one.
    """
    n, missing = model.n_states, model.missing()
    extra = 1 if missing else 0
    head = [] if model.comment is None else [f"// {model.comment}"]
    yield "\n".join([*head, f"@type: {model.kind}", "@parameters", "", "@reward_models",
                     " ".join(r.name for r in model.rewards), "@nr_states", str(n + extra),
                     "@nr_choices", str(model.n_choices + extra), "@model"]) + "\n"
    pieces = _Pieces(model)
    for lo in range(0, n, CHUNK_STATES):
        yield pieces.chunk(lo, min(n, lo + CHUNK_STATES))
    if missing:
        yield pieces.declaring(missing)


class _Pieces:
    """The strings a model's lines are made of, and the chunks made of them."""

    def __init__(self, model: DrnModel) -> None:
        self.model = model
        self.row_groups = np.asarray(model.row_groups, dtype=np.int64)
        self.names = ["init", *(name for name, _ in model.labels)]
        self.masks = [np.asarray(mask, dtype=bool) for _, mask in model.labels]
        state_r = [r.state for r in model.rewards]
        choice_r = [r.choice for r in model.rewards]
        self.state_rewards = _reward_columns(state_r, model.n_states)
        self.choice_rewards = _reward_columns(choice_r, model.n_choices)
        # an action line ends with the choice's rewards, if any, else here
        self.end = "" if self.choice_rewards is not None else "\n"
        if model.action_names is None:
            self.action_lines = None
        else:
            self.action_lines = np.array(
                [f"\taction {action_token(a)}{self.end}" for a in model.action_names]
                + [f"\taction absorb{self.end}"], dtype=object)  # ABSORB (-1) is the last
            self.actions = np.asarray(model.choice_actions, dtype=np.int64)

    def chunk(self, lo: int, hi: int) -> str:
        """The lines of states ``lo .. hi-1``."""
        model, rg = self.model, self.row_groups
        matrix = model.matrix
        c_lo, c_hi = int(rg[lo]), int(rg[hi])
        p_lo, p_hi = int(matrix.indptr[c_lo]), int(matrix.indptr[c_hi])
        cols = np.asarray(matrix.indices[p_lo:p_hi])
        vals = np.asarray(matrix.data[p_lo:p_hi])
        ups = None if model.upper is None else np.asarray(model.upper[p_lo:p_hi])
        entry_row = np.repeat(np.arange(c_hi - c_lo),
                              np.diff(np.asarray(matrix.indptr[c_lo:c_hi + 1], np.int64)))
        keep = (vals if ups is None else ups) > 0
        cols, vals, entry_row = cols[keep], vals[keep], entry_row[keep]
        ups = None if ups is None else ups[keep]
        if np.any((np.diff(cols) < 0) & (entry_row[1:] == entry_row[:-1])):
            order = np.lexsort((cols, entry_row))  # successors in increasing order
            cols, vals, entry_row = cols[order], vals[order], entry_row[order]
            ups = None if ups is None else ups[order]
        row_len = np.bincount(entry_row, minlength=c_hi - c_lo)
        # Places: per state its head, then per choice its action line and two pieces
        # (successor, probability) per entry.
        before = np.concatenate([[0], np.cumsum(1 + 2 * row_len)])
        owner = np.repeat(np.arange(hi - lo), np.diff(rg[lo:hi + 1]))
        choice_at = owner + 1 + before[:-1]
        state_at = np.arange(hi - lo) + before[rg[lo:hi] - c_lo]
        first = np.concatenate([[0], np.cumsum(row_len)])
        entry_at = choice_at[entry_row] + 1 + 2 * (np.arange(cols.size) - first[entry_row])
        pieces = np.empty(hi - lo + c_hi - c_lo + 2 * cols.size, dtype=object)
        pieces[choice_at] = self._actions(c_lo, c_hi, rg[lo:hi][owner])
        pieces[entry_at] = _successors(cols)
        pieces[entry_at + 1] = _values(vals, ups)
        pieces[state_at] = self._heads(lo, hi)
        return "".join(pieces.tolist())

    def _actions(self, c_lo: int, c_hi: int, first: np.ndarray) -> np.ndarray:
        """The action lines of choices ``c_lo .. c_hi-1`` (``first``: each one's state's
        first choice)."""
        if self.action_lines is None:  # the choice's index in its state
            local = np.arange(c_lo, c_hi) - first
            table = np.array([f"\taction {j}{self.end}"
                              for j in range(int(local.max(initial=0)) + 1)], dtype=object)
            lines = table[local]
        else:
            lines = self.action_lines[self.actions[c_lo:c_hi]]
        if self.choice_rewards is None:
            return lines
        return lines + _bracketed(self.choice_rewards, c_lo, c_hi) + "\n"

    def _heads(self, lo: int, hi: int) -> list[str]:
        """The state lines (with their valuations) of states ``lo .. hi-1``."""
        marks = np.zeros((hi - lo, len(self.names)), dtype=bool)
        marks[:, 0] = np.arange(lo, hi) == int(self.model.initial)
        for k, mask in enumerate(self.masks, start=1):
            marks[:, k] = mask[lo:hi]
        # the distinct label sets, by one integer each (a sort of rows is several times
        # slower) while the labels fit in one
        key = (marks @ (1 << np.arange(marks.shape[1], dtype=np.int64))
               if marks.shape[1] < 63 else marks)
        _, first, which = np.unique(key, axis=0, return_index=True, return_inverse=True)
        labels = ["".join(f" {name}" for name, on in zip(self.names, row, strict=True) if on)
                  for row in marks[first].tolist()]
        texts = [labels[k] for k in which.reshape(-1).tolist()]
        if self.state_rewards is not None:
            rewards = _bracketed(self.state_rewards, lo, hi)
            texts = [r + t for r, t in zip(rewards.tolist(), texts, strict=True)]
        if self.model.valuations is None:
            return [f"state {s}{t}\n" for s, t in zip(range(lo, hi), texts, strict=True)]
        return [f"state {s}{t}\n//[{v}]\n" for s, t, v in
                zip(range(lo, hi), texts, self.model.valuations[lo:hi], strict=True)]

    def declaring(self, missing: tuple[str, ...]) -> str:
        """The state after the others that carries the declared labels no state does
        (module docstring): reached by none, looping on itself."""
        n = self.model.n_states
        rewards = ""
        if self.state_rewards is not None:
            rewards = _bracketed([np.zeros(1, c.dtype) for c in self.state_rewards], 0, 1)[0]
        lines = f"state {n}{rewards} {' '.join(missing)}\n"
        if self.model.valuations is not None:
            lines += f"//[unreachable: declares the label{'s' * (len(missing) > 1)}]\n"
        lines += "\taction absorb" if self.action_lines is not None else "\taction 0"
        if self.choice_rewards is not None:
            lines += _bracketed([np.zeros(1, c.dtype) for c in self.choice_rewards], 0, 1)[0]
        one = "1.0" if self.model.upper is None else "[1.0, 1.0]"
        return lines + f"\n\t\t{n} : {one}\n"


def _reward_columns(values: list[np.ndarray | None], size: int) -> list[np.ndarray] | None:
    """One column per reward model (integer zeros where a model has none of this kind),
    or None when no model has any."""
    if all(v is None for v in values):
        return None
    return [np.zeros(size, np.int64) if v is None else np.asarray(v) for v in values]


def _bracketed(columns: list[np.ndarray], lo: int, hi: int) -> np.ndarray:
    """``" [r1, r2]"`` for entries ``lo .. hi-1`` of the reward columns (object array)."""
    out: np.ndarray | None = None
    for k, column in enumerate(columns):
        table, index = _strings(column[lo:hi], repr)
        part = (" [" if k == 0 else ", ") + table[index]
        out = part if out is None else out + part
    assert out is not None
    return out + "]"


def _strings(values: np.ndarray, fmt: Callable[[object], str]) -> tuple[np.ndarray, np.ndarray]:
    """``(table, index)``: ``fmt`` of each distinct entry of ``values`` once, as an object
    array, and where each entry's string is in it."""
    distinct, index = np.unique(values, return_inverse=True)
    table = np.empty(distinct.shape[0], dtype=object)
    table[:] = [fmt(v) for v in distinct.tolist()]
    return table, index.reshape(-1)


def _values(vals: np.ndarray, ups: np.ndarray | None) -> np.ndarray:
    """The probability pieces: ``"{p!r}\\n"``, or ``"[{lo!r}, {hi!r}]\\n"``."""
    if ups is None:
        table, index = _strings(vals, lambda v: f"{v!r}\n")
        return table[index]
    low, at_low = _strings(vals, lambda v: f"[{v!r}, ")
    high, at_high = _strings(ups, lambda v: f"{v!r}]\n")
    return low[at_low] + high[at_high]


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

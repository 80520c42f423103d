"""A world that is already a table: its states, labels, actions and moves as arrays.

A world whose moves do not depend on the step's events and that holds them as sparse
arrays (a PRISM program built by Storm, :mod:`mitld_lp.worlds.prism`) can hand them to
the product construction whole, through a method ``as_table()`` returning a
:class:`WorldTable` (or ``None`` when it cannot, e.g. a PRISM world whose events change
it).  The product then reads the table with array operations
(:class:`mitld_lp.product.layers.Layers`) instead of asking :meth:`Game.actions`,
:meth:`Game.successors` and :meth:`Game.propositions` once per state, action and events:
the same product, bit for bit, without a Python object per state.

The table must say exactly what the world's :class:`~mitld_lp.worlds.game.Game` methods
say (a test holds the PRISM world to it): state ``i`` is ``states[i]``, its
propositions ``label_sets[label_of[i]]``, its actions (in the game's order) the
choices ``choices[i]:choices[i+1]``, choice ``c`` named ``action_names[action_of[c]]``
with the successors ``targets[branches[c]:branches[c+1]]`` (state indices) and their
probabilities, in the order :meth:`Game.successors` lists them.

A world may leave some choices' names to be made when first read (a PRISM program's
unlabelled commands: :mod:`mitld_lp.worlds.prism_names`): its ``action_names`` is then a
:class:`LateNames`, whose ids from :data:`LATE` on name one choice each (``LATE + c``:
robot choice ``c``); the product passes such ids on and names them when the MDP's names
are first read (:mod:`mitld_lp.product.late_names`).
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["LATE", "LateNames", "WorldTable", "table_of"]

LATE = 1 << 30
"""The first id of a choice whose name is made when first read (:class:`LateNames`)."""


class LateNames(Sequence[str]):
    """A world's action names where some choices are named when first read: ``len``,
    iteration and ids below :data:`LATE` are the names known at once (a tuple's
    answers); id ``LATE + c`` is robot choice ``c``'s name, made on first use
    (:meth:`names_of`)."""

    known: tuple[str, ...]

    def names_of(self, choices: np.ndarray) -> tuple[np.ndarray, tuple[str, ...]]:
        """``(codes, names)``: the name of each of ``choices`` (robot choice indices)
        as ``names[codes[i]]``."""
        raise NotImplementedError

    def __len__(self) -> int:
        return len(self.known)

    def __iter__(self) -> Any:
        return iter(self.known)

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, int | np.integer) and int(i) >= LATE:
            codes, names = self.names_of(np.array([int(i) - LATE], dtype=np.int64))
            return names[int(codes[0])]
        return self.known[i]

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.known!r} and choices named when first read)"


@dataclass(frozen=True, eq=False)
class WorldTable:
    """A world's states, labels, actions and moves as arrays (``n`` states, ``m`` robot
    choices, ``b`` branches); see the module docstring.

    Attributes:
        states: the ``n`` states (hashable), indexable by state number.
        initial: the initial state's number.
        label_sets: the distinct proposition sets.
        label_of: ``n`` indices into ``label_sets``.
        choices: ``n + 1`` offsets into the robot's choices (every state has one).
        action_names: the distinct action names (a :class:`LateNames` where some are
            made when first read).
        action_of: ``m`` indices into ``action_names`` (distinct within a state; from
            :data:`LATE` on, a choice named when first read).
        branches: ``m + 1`` offsets into ``targets`` and ``probabilities``.
        targets: ``b`` state numbers.
        probabilities: ``b`` probabilities (float64).
        checked: every row is known to be a distribution within
            :data:`~mitld_lp.worlds.successors.PROBABILITY_TOLERANCE`, checked where
            the table was made (a PRISM world's, :func:`mitld_lp.worlds.prism_tables.read_model`):
            the product does not check the rows again (False: it checks every row).
    """

    states: Sequence[Hashable]
    initial: int
    label_sets: tuple[frozenset[str], ...]
    label_of: np.ndarray
    choices: np.ndarray
    action_names: Sequence[str]
    action_of: np.ndarray
    branches: np.ndarray
    targets: np.ndarray
    probabilities: np.ndarray
    checked: bool = False

    def __post_init__(self) -> None:
        n, m = len(self.states), self.action_of.size
        b = self.targets.size
        ok = (
            n >= 1 and 0 <= self.initial < n and self.label_of.shape == (n,)
            and self.choices.shape == (n + 1,) and int(self.choices[-1]) == m
            and self.branches.shape == (m + 1,) and self.probabilities.shape == (b,)
            and int(self.choices[0]) == 0 and int(self.branches[0]) == 0
            and int(self.branches[-1]) == b
            and bool(np.all(np.diff(self.choices) > 0))
            and bool(np.all(np.diff(self.branches) > 0))
            and (b == 0 or (int(self.targets.min()) >= 0 and int(self.targets.max()) < n))
            and (m == 0 or (int(self.action_of.min()) >= 0
                            and (int(self.action_of.max()) < len(self.action_names)
                                 or isinstance(self.action_names, LateNames))))
            and (int(self.label_of.min()) >= 0
                 and int(self.label_of.max()) < len(self.label_sets))
        )
        if not ok:
            raise ValueError("a WorldTable's arrays do not fit together")

    @property
    def n_states(self) -> int:
        return len(self.states)

    def owner(self, choice: int) -> int:
        """The state of robot choice ``choice``."""
        return int(np.searchsorted(self.choices, choice, side="right")) - 1


def table_of(world: Any) -> WorldTable | None:
    """The world's :class:`WorldTable` when it offers one (``as_table()``), else None."""
    method = getattr(type(world), "as_table", None)
    if method is None:
        return None
    table = method(world)
    return table if isinstance(table, WorldTable) else None

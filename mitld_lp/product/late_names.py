"""The product's action names where the world names some choices when first read.

A world whose table leaves choices unnamed (:class:`mitld_lp.worlds.table.LateNames`:
a PRISM program's unlabelled commands, :mod:`mitld_lp.worlds.prism_names`) makes the
product give each of its choices the id ``LATE + c`` (robot choice ``c`` of the world)
in its ``choice_actions``, and its ``action_names`` is a :class:`LateActionNames`: the
first read of the names (``len``, iteration, an id) asks the world for the choices'
names, numbers them in order of first use (as the product numbers a world's names) and
writes their ids into ``choice_actions`` in place, so that the MDP then reads as the one
built with every name known, id for id.  An id ``LATE + c``
copied from ``choice_actions`` before that still names its choice (``names[LATE + c]``),
and is out of range of every list made from the names: never a wrong name.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from mitld_lp.worlds.table import LATE, LateNames

__all__ = ["LateActionNames"]


class LateActionNames(Sequence[str]):
    """An MDP's action names, made when first read (the module docstring): ``world``
    the world's names, ``actions`` the MDP's ``choice_actions`` (``LATE + c`` for the
    world's robot choice ``c``; rewritten in place when named)."""

    def __init__(self, world: LateNames, actions: np.ndarray) -> None:
        self.world = world
        self.actions = actions
        self._names: tuple[str, ...] | None = None

    @property
    def resolved(self) -> bool:
        """Whether the choices are named yet."""
        return self._names is not None

    def names(self) -> tuple[str, ...]:
        """Every name, in order of first use (the choices' ids written into
        ``actions``)."""
        if self._names is None:
            late = np.flatnonzero(self.actions >= LATE)
            codes, names = self.world.names_of(self.actions[late].astype(np.int64) - LATE)
            used, first = np.unique(codes, return_index=True)
            order = used[np.argsort(first)]
            ids = np.full(len(names), -1, dtype=np.int64)
            ids[order] = np.arange(order.size)
            self.actions[late] = ids[codes]
            self._names = tuple(names[k] for k in order.tolist())
        return self._names

    def __len__(self) -> int:
        return len(self.names())

    def __iter__(self) -> Any:
        return iter(self.names())

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, int | np.integer) and int(i) >= LATE:  # copied before named
            return self.world[int(i)]
        return self.names()[i]

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Sequence) and not isinstance(other, str):
            return tuple(self) == tuple(other)
        return NotImplemented

    def __hash__(self) -> int:
        return hash(self.names())

    def __repr__(self) -> str:
        if self._names is None:
            return "LateActionNames(<named when first read>)"
        return f"LateActionNames({self._names!r})"

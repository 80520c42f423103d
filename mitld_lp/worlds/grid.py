"""The grid world of the case study, as a :class:`mitld_lp.worlds.game.Game`.

States are the free cells ``(x, y)`` of a ``width x height`` grid (E is +x, N is +y).
The robot's actions are the compass moves ``N, S, E, W``.  A move reaches the intended
neighbour with probability ``1 - 2*slip`` and each perpendicular neighbour with
probability ``slip``; an outcome that would leave the grid or enter an obstacle leaves
the robot where it is (the paper's "bouncing wall"), and outcomes landing on the same
cell are merged.  The dynamics ignore the external events.

Nothing is tabulated on construction (a 1000 x 1000 grid costs what its obstacles and
regions cost): a successor distribution is computed the first time a (cell, action) is
asked and then kept, so asking again is one dictionary lookup and returns the same
tuple.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from numbers import Real
from types import MappingProxyType
from typing import Any, ClassVar, cast

from mitld_lp.logic.syntax import RESERVED, is_proposition_name
from mitld_lp.util.decimals import Written, exact_value

__all__ = ["Cell", "GridWorld", "GridError", "ACTIONS", "STAY", "MOVES", "PERPENDICULAR"]

Cell = tuple[int, int]
"""A grid cell ``(x, y)``."""

ACTIONS: tuple[str, ...] = ("N", "S", "E", "W")
"""The robot's moves, in the order :meth:`GridWorld.actions` returns them."""

STAY = "stay"
"""The action of staying put (only in a world made with ``stay=True``), after the moves."""

MOVES: Mapping[str, Cell] = MappingProxyType({"N": (0, 1), "S": (0, -1), "E": (1, 0), "W": (-1, 0)})
"""The displacement ``(dx, dy)`` of each action."""

PERPENDICULAR: Mapping[str, tuple[str, str]] = MappingProxyType(
    {"N": ("E", "W"), "S": ("W", "E"), "E": ("N", "S"), "W": ("S", "N")}
)
"""The two directions a move may slip into."""


_NOWHERE: frozenset[str] = frozenset()
_WITH_STAY = (*ACTIONS, STAY)


def _is_int(x: object) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


PathPart = str | int
"""A field name, a region name or an index in a :class:`GridError` path."""


def _format_path(parts: Sequence[PathPart]) -> str:
    """``regions.A[0]``; a name that is not a bare word is quoted (``regions."a b"``)."""
    out = ""
    for p in parts:
        if isinstance(p, int):
            out += f"[{p}]"
        else:
            word = p if re.fullmatch(r"[A-Za-z0-9_-]+", p) else json.dumps(p)
            out += f".{word}" if out else word
    return out


class GridError(ValueError):
    """A bad value for a :class:`GridWorld`, with its place: ``parts`` is the path to it
    (``("regions", "A", 0)``: the first cell of region ``A`` as given), ``path`` the
    same as text (``regions.A[0]``) and ``message`` what is wrong; ``str(error)`` is
    ``"path: message"``.  A loader maps ``parts`` to its own key path."""

    def __init__(self, parts: Sequence[PathPart], message: str) -> None:
        self.parts = tuple(parts)
        self.path = _format_path(self.parts)
        self.message = message
        super().__init__(f"{self.path}: {message}")

    def __reduce__(self) -> tuple[Any, ...]:
        return (GridError, (self.parts, self.message))


@dataclass(frozen=True, slots=True)
class GridWorld:
    """A ``width x height`` grid world with slippery compass moves.

    Attributes:
        width: number of columns (x in ``0..width-1``).
        height: number of rows (y in ``0..height-1``).
        start: the initial cell.
        slip: probability of each perpendicular outcome, in ``[0, 0.5]``.
        obstacles: cells the robot can never enter.
        regions: ``(name, cells)`` pairs sorted by name; ``name`` is a robot
            proposition true exactly on ``cells`` (a name a formula can write: letters,
            digits and ``_``, not a reserved word such as ``F``; at least one cell).
            The constructor also accepts a mapping ``name -> cells`` (any collections
            of cells), and any collection for ``obstacles``, and normalises them, so
            equal worlds compare and hash equal.
        stay: whether the robot also has the action ``"stay"`` (remain in the cell with
            probability 1; no slip).  Off by default.

    Raises :class:`GridError` (a ``ValueError``) with the path of the bad value
    (``regions.A[0]``): a non-positive size, a cell off the grid or listed twice, a
    start or region cell on an obstacle, ``slip`` out of range, a region name a formula
    cannot write, an empty region.
    """

    width: int
    height: int
    start: Cell = (0, 0)
    slip: float = 0.0
    obstacles: frozenset[Cell] = frozenset()
    regions: tuple[tuple[str, frozenset[Cell]], ...] = ()
    stay: bool = False
    _succ: dict[tuple[Cell, str], tuple[tuple[Cell, float], ...]] = field(
        init=False, repr=False, compare=False, hash=False
    )
    _labels: dict[Cell, frozenset[str]] = field(
        init=False, repr=False, compare=False, hash=False
    )
    _exact_slip: Fraction = field(init=False, repr=False, compare=False, hash=False)

    ignores_events: ClassVar[bool] = True
    """The moves do not depend on the external events
    (:class:`mitld_lp.worlds.game.WorldMembers`)."""

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            v = getattr(self, name)
            if not _is_int(v) or v < 1:
                raise GridError([name], f"must be a positive integer, got {v!r}")
        slip = self.slip
        if not isinstance(slip, Real) or isinstance(slip, bool) or not math.isfinite(slip):
            raise GridError(["slip"], f"must be a number, got {slip!r}")
        if not 0.0 <= slip <= 0.5:
            raise GridError(["slip"], f"must be in [0, 0.5], got {slip!r}")
        if not isinstance(self.stay, bool):
            raise GridError(["stay"], f"must be True or False, got {self.stay!r}")
        obstacles = self._cells(self.obstacles, ["obstacles"])
        start = self._cell(self.start, ["start"])
        if start in obstacles:
            raise GridError(["start"], f"cell {self.start!r} is an obstacle")
        regions = self._regions(obstacles)
        object.__setattr__(self, "start", start)
        # slip as written (mitld_lp.util.decimals), for the exact successors; a decimal
        # read from text stays a Written float, so that a copy (replace) keeps its text
        object.__setattr__(self, "_exact_slip", exact_value(slip))
        object.__setattr__(self, "slip", slip if isinstance(slip, Written) else float(slip))
        object.__setattr__(self, "obstacles", frozenset(obstacles))
        object.__setattr__(self, "regions", tuple(sorted(regions.items())))
        object.__setattr__(self, "_succ", {})
        labels: dict[Cell, set[str]] = {}
        for rname, cells in regions.items():
            for c in cells:
                labels.setdefault(c, set()).add(rname)
        object.__setattr__(self, "_labels", {c: frozenset(v) for c, v in labels.items()})

    def _cell(self, value: Any, parts: list[PathPart]) -> Cell:
        """``value`` as a cell of the grid."""
        try:
            x, y = value
        except (TypeError, ValueError):
            raise GridError(parts, f"must be a cell (x, y), got {value!r}") from None
        if not (_is_int(x) and _is_int(y)):
            raise GridError(parts, f"must be a cell of two integers, got {value!r}")
        if not (0 <= x < self.width and 0 <= y < self.height):
            raise GridError(
                parts,
                f"cell {value!r} is off the {self.width}x{self.height} grid "
                f"(x in 0..{self.width - 1}, y in 0..{self.height - 1})",
            )
        return (x, y)

    def _cells(self, values: Any, parts: list[PathPart]) -> dict[Cell, Any]:
        """Cells of the grid, each once (an index in the path when they come in an order);
        each with the value it was given as."""
        if isinstance(values, str) or not isinstance(values, Iterable):
            raise GridError(parts, f"must be a collection of cells, got {values!r}")
        ordered = isinstance(values, Sequence)
        out: dict[Cell, Any] = {}
        for i, v in enumerate(values):
            where = [*parts, i] if ordered else parts
            c = self._cell(v, where)
            if c in out:
                raise GridError(where, f"cell {v!r} is listed twice")
            out[c] = v
        return out

    def _regions(self, obstacles: Mapping[Cell, Any]) -> dict[str, frozenset[Cell]]:
        """Named, non-empty sets of free cells, named as a formula can write them."""
        raw = self.regions.items() if isinstance(self.regions, Mapping) else self.regions
        regions: dict[str, frozenset[Cell]] = {}
        for item in raw:
            try:
                rname, rcells = item
            except (TypeError, ValueError):
                raise GridError(["regions"], f"expected (name, cells), got {item!r}") from None
            if not is_proposition_name(rname):
                shown = json.dumps(rname) if isinstance(rname, str) else repr(rname)
                raise GridError(
                    ["regions", rname if isinstance(rname, str) else repr(rname)],
                    f"region name {shown} is not a proposition name (letters, digits, "
                    "'_', not starting with a digit, not one of "
                    f"{', '.join(sorted(RESERVED))})",
                )
            if rname in regions:
                raise GridError(["regions", rname], "given twice")
            cells = self._cells(rcells, ["regions", rname])
            if not cells:
                raise GridError(["regions", rname], "must list at least one cell")
            ordered = isinstance(rcells, Sequence)
            for i, (c, v) in enumerate(cells.items()):
                if c in obstacles:
                    where: list[PathPart] = ["regions", rname, *([i] if ordered else [])]
                    raise GridError(where, f"cell {v!r} is an obstacle")
            regions[rname] = frozenset(cells)
        return regions

    def _is_free(self, state: Any) -> bool:
        try:
            x, y = state
        except (TypeError, ValueError):
            return False
        return (
            _is_int(x) and _is_int(y) and 0 <= x < self.width and 0 <= y < self.height
            and (x, y) not in self.obstacles
        )

    def _distribution(self, cell: Cell, action: str, exact: bool = False,
                      ) -> tuple[tuple[Cell, Any], ...]:
        """``P(c, a)``: intended neighbour ``1 - 2*slip``, each perpendicular ``slip``,
        blocked outcomes stay at ``c``, merged by landing cell, zero outcomes dropped
        (``exact``: in rationals, from ``slip`` as written)."""
        x, y = cell
        slip = self._exact_slip if exact else self.slip
        intended, side = 1 - 2 * slip, slip
        left, right = PERPENDICULAR[action]
        dist: dict[Cell, Any] = {}
        for direction, p in ((action, intended), (left, side), (right, side)):
            if p <= 0.0:
                continue
            dx, dy = MOVES[direction]
            nx, ny = x + dx, y + dy
            if not (0 <= nx < self.width and 0 <= ny < self.height) or (
                nx, ny) in self.obstacles:
                nx, ny = x, y
            dist[nx, ny] = dist.get((nx, ny), 0) + p
        return tuple(dist.items())

    # ------------------------------------------------------------------ Game protocol

    @property
    def initial(self) -> Cell:
        """The start cell."""
        return self.start

    @property
    def proposition_names(self) -> frozenset[str]:
        """The region names."""
        return frozenset(name for name, _ in self.regions)

    def actions(self, state: Cell) -> tuple[str, ...]:
        """``("N", "S", "E", "W")`` at every cell, then ``"stay"`` if the world has it."""
        return _WITH_STAY if self.stay else ACTIONS

    def successors(
        self, state: Cell, action: str, events: frozenset[str] = frozenset()
    ) -> tuple[tuple[Cell, float], ...]:
        """The distribution over next cells (computed once per cell and action, then the
        same tuple); ``events`` is ignored."""
        key = (state, action)
        hit = self._succ.get(key)
        if hit is None:
            known = action in MOVES or (self.stay and action == STAY)
            if not known or not self._is_free(state):
                raise ValueError(
                    f"no move {action!r} from {state!r}: not a free cell of the grid or "
                    f"not one of {self.actions(state)}"
                )
            hit = self._succ[key] = (
                ((state, 1.0),) if action == STAY else self._distribution(state, action)
            )
        return hit

    def exact_successors(
        self, state: Cell, action: str, events: frozenset[str] = frozenset()
    ) -> tuple[tuple[Cell, Fraction], ...]:
        """:meth:`successors` in rational arithmetic, from ``slip`` as written
        (:mod:`mitld_lp.worlds.exact`): the same next cells in the same order."""
        self.successors(state, action, events)  # the same checks of the state and action
        if action == STAY:
            return ((state, Fraction(1)),)
        return self._distribution(state, action, exact=True)

    def propositions(self, state: Cell) -> frozenset[str]:
        """The names of the regions containing ``state``."""
        hit = self._labels.get(state)
        if hit is None:
            if not self._is_free(state):
                raise ValueError(f"{state!r} is not a free cell of the grid")
            return _NOWHERE
        return hit

    # ------------------------------------------------------------------ helpers

    @property
    def n_states(self) -> int:
        """The number of free cells (the game's states)."""
        return self.width * self.height - len(self.obstacles)

    @property
    def cells(self) -> tuple[Cell, ...]:
        """Every free cell, x-major then y."""
        return tuple(
            (x, y)
            for x in range(self.width)
            for y in range(self.height)
            if (x, y) not in self.obstacles
        )

    @property
    def region_map(self) -> Mapping[str, frozenset[Cell]]:
        """The regions as a read-only mapping ``name -> cells``."""
        return MappingProxyType(dict(self.regions))

    @classmethod
    def make(
        cls,
        width: int,
        height: int,
        *,
        start: Iterable[int] = (0, 0),
        slip: float = 0.0,
        obstacles: Iterable[Iterable[int]] = (),
        regions: Mapping[str, Iterable[Iterable[int]]] | None = None,
        stay: bool = False,
    ) -> GridWorld:
        """Build from plain values (lists for cells, a dict of regions); the constructor
        validates and normalises them (errors name the index of a cell in its list)."""
        return cls(
            width=width,
            height=height,
            start=cast(Cell, tuple(start)),
            slip=slip,
            # lists: the constructor validates them with indices and freezes them
            obstacles=cast(Any, [tuple(c) for c in obstacles]),
            regions=cast(Any, [(k, [tuple(c) for c in v]) for k, v in (regions or {}).items()]),
            stay=stay,
        )

"""The grid world of the case study, as a :class:`mitld_lp.game.Game`.

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

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from numbers import Real
from types import MappingProxyType
from typing import Any, ClassVar, cast

__all__ = ["Cell", "GridWorld", "ACTIONS", "MOVES", "PERPENDICULAR"]

Cell = tuple[int, int]
"""A grid cell ``(x, y)``."""

ACTIONS: tuple[str, ...] = ("N", "S", "E", "W")
"""The robot's actions, in the order :meth:`GridWorld.actions` returns them."""

MOVES: Mapping[str, Cell] = MappingProxyType({"N": (0, 1), "S": (0, -1), "E": (1, 0), "W": (-1, 0)})
"""The displacement ``(dx, dy)`` of each action."""

PERPENDICULAR: Mapping[str, tuple[str, str]] = MappingProxyType(
    {"N": ("E", "W"), "S": ("W", "E"), "E": ("N", "S"), "W": ("S", "N")}
)
"""The two directions a move may slip into."""


_NOWHERE: frozenset[str] = frozenset()


def _is_int(x: object) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _cell(value: Any, what: str) -> Cell:
    try:
        x, y = value
    except (TypeError, ValueError):
        raise ValueError(f"{what}: must be a cell (x, y), got {value!r}") from None
    if not (_is_int(x) and _is_int(y)):
        raise ValueError(f"{what}: must be a cell of two integers, got {value!r}")
    return (x, y)


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
            proposition true exactly on ``cells``.  The constructor also accepts a
            mapping ``name -> cells`` (any iterables of cells), and frozen sets for
            ``obstacles``, and normalises them, so equal worlds compare and hash equal.

    Raises ``ValueError`` naming the field on a bad value: a non-positive size, a cell
    off the grid, a start or region cell on an obstacle, ``slip`` out of range.
    """

    width: int
    height: int
    start: Cell = (0, 0)
    slip: float = 0.0
    obstacles: frozenset[Cell] = frozenset()
    regions: tuple[tuple[str, frozenset[Cell]], ...] = ()
    _succ: dict[tuple[Cell, str], tuple[tuple[Cell, float], ...]] = field(
        init=False, repr=False, compare=False, hash=False
    )
    _labels: Mapping[Cell, frozenset[str]] = field(
        init=False, repr=False, compare=False, hash=False
    )

    ignores_events: ClassVar[bool] = True
    """The moves do not depend on the external events (see :class:`mitld_lp.game.Game`)."""

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            v = getattr(self, name)
            if not _is_int(v) or v < 1:
                raise ValueError(f"{name}: must be a positive integer, got {v!r}")
        slip = self.slip
        if not isinstance(slip, Real) or isinstance(slip, bool) or not math.isfinite(slip):
            raise ValueError(f"slip: must be a number, got {slip!r}")
        if not 0.0 <= slip <= 0.5:
            raise ValueError(f"slip: must be in [0, 0.5], got {slip!r}")
        obstacles = frozenset(_cell(c, "obstacles") for c in self.obstacles)
        for c in obstacles:
            self._check_on_grid(c, "obstacles")
        start = _cell(self.start, "start")
        self._check_on_grid(start, "start")
        if start in obstacles:
            raise ValueError(f"start: {start} is an obstacle")
        raw = self.regions.items() if isinstance(self.regions, Mapping) else self.regions
        regions: dict[str, frozenset[Cell]] = {}
        for item in raw:
            try:
                rname, rcells = item
            except (TypeError, ValueError):
                raise ValueError(f"regions: expected (name, cells), got {item!r}") from None
            if not isinstance(rname, str) or not rname:
                raise ValueError(f"regions: name must be a non-empty string, got {rname!r}")
            if rname in regions:
                raise ValueError(f"regions.{rname}: given twice")
            cells = frozenset(_cell(c, f"regions.{rname}") for c in rcells)
            for c in cells:
                self._check_on_grid(c, f"regions.{rname}")
                if c in obstacles:
                    raise ValueError(f"regions.{rname}: {c} is an obstacle")
            regions[rname] = cells
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "slip", float(slip))
        object.__setattr__(self, "obstacles", obstacles)
        object.__setattr__(self, "regions", tuple(sorted(regions.items())))
        object.__setattr__(self, "_succ", {})
        labels: dict[Cell, set[str]] = {}
        for rname, cells in regions.items():
            for c in cells:
                labels.setdefault(c, set()).add(rname)
        object.__setattr__(
            self, "_labels", MappingProxyType({c: frozenset(v) for c, v in labels.items()})
        )

    def _check_on_grid(self, cell: Cell, what: str) -> None:
        x, y = cell
        if not (0 <= x < self.width and 0 <= y < self.height):
            raise ValueError(
                f"{what}: {cell} is off the {self.width}x{self.height} grid "
                f"(x in 0..{self.width - 1}, y in 0..{self.height - 1})"
            )

    def _is_free(self, state: Any) -> bool:
        try:
            x, y = state
        except (TypeError, ValueError):
            return False
        return (
            _is_int(x) and _is_int(y) and 0 <= x < self.width and 0 <= y < self.height
            and (x, y) not in self.obstacles
        )

    def _distribution(self, cell: Cell, action: str) -> tuple[tuple[Cell, float], ...]:
        """``P(c, a)``: intended neighbour ``1 - 2*slip``, each perpendicular ``slip``,
        blocked outcomes stay at ``c``, merged by landing cell, zero outcomes dropped."""
        x, y = cell
        intended, side = 1.0 - 2.0 * self.slip, self.slip
        left, right = PERPENDICULAR[action]
        dist: dict[Cell, float] = {}
        for direction, p in ((action, intended), (left, side), (right, side)):
            if p <= 0.0:
                continue
            dx, dy = MOVES[direction]
            nx, ny = x + dx, y + dy
            if not (0 <= nx < self.width and 0 <= ny < self.height) or (
                nx, ny) in self.obstacles:
                nx, ny = x, y
            dist[nx, ny] = dist.get((nx, ny), 0.0) + p
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
        """``("N", "S", "E", "W")`` at every cell."""
        return ACTIONS

    def successors(
        self, state: Cell, action: str, events: frozenset[str] = frozenset()
    ) -> tuple[tuple[Cell, float], ...]:
        """The distribution over next cells (computed once per cell and action, then the
        same tuple); ``events`` is ignored."""
        key = (state, action)
        hit = self._succ.get(key)
        if hit is None:
            if action not in MOVES or not self._is_free(state):
                raise ValueError(
                    f"no move {action!r} from {state!r}: not a free cell of the grid or "
                    f"not one of {ACTIONS}"
                )
            hit = self._succ[key] = self._distribution(state, action)
        return hit

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
    ) -> GridWorld:
        """Build from plain values (lists for cells, a dict of regions); the constructor
        validates and normalises them."""
        return cls(
            width=width,
            height=height,
            start=cast(Cell, tuple(start)),
            slip=slip,
            obstacles=frozenset(cast(Cell, tuple(c)) for c in obstacles),
            regions=tuple(
                (k, frozenset(cast(Cell, tuple(c)) for c in v)) for k, v in (regions or {}).items()
            ),
        )

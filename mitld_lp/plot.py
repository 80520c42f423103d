"""Pictures: the policy of a grid world, and a sweep's results.

* :func:`policy_map` reads, for one *situation* (which events are pending, which have
  just happened, the automaton's state), the policy's action and its success
  probability at every cell of a grid world; :func:`policy_figure` draws one panel per
  situation: a cell's colour is the probability of success from there (the policy's
  exact value, truncation counted as failure), an arrow its action; obstacles are
  black, regions outlined and named, cells where the task is already decided say so.
* :func:`sweep_figure` draws a column of a sweep's results file against a parameter,
  one line per combination of the other parameters.

matplotlib is imported only here, through its object API on the Agg canvas (no pyplot,
no global backend switch).  Figures have the exact pixel ``size`` asked for.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mitld_lp.files import write as files
from mitld_lp.worlds.grid import MOVES, STAY, Cell, GridWorld

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from mitld_lp.result import Result as SynthesisResult

__all__ = ["PlotError", "Situation", "CellView", "PolicyMap", "parse_situation", "policy_map",
           "policy_figure", "sweep_figure", "save", "FIGURE_SUFFIXES"]

FIGURE_SUFFIXES = (".png", ".svg", ".pdf")
DEFAULT_SIZE = (800, 600)
_DPI = 100

OPEN, DONE, FAILED, UNREACHED = "open", "done", "failed", "unreached"


class PlotError(ValueError):
    """A picture cannot be drawn as asked (a bad situation, a world that is no grid, a
    column the results do not have)."""


@dataclass(frozen=True, slots=True)
class Situation:
    """Which product states a policy picture shows, one per cell.

    Attributes:
        pending: the events that have not happened (default: all but ``occurred``).
        occurred: events that happen in the step that enters each cell; the automaton's
            state at a cell is then its step from ``automaton`` on the cell's
            propositions and these events (default: none, the automaton stays at
            ``automaton`` everywhere).
        automaton: the automaton's state (default: the initial product state's).
        clock: the steps counted for the pending events (default: the smallest the
            product reaches at that cell).
    """

    pending: frozenset[str] | None = None
    occurred: frozenset[str] = frozenset()
    automaton: int | None = None
    clock: int | None = None

    def __str__(self) -> str:
        parts = []
        if self.pending is not None:
            parts.append("pending=" + ",".join(sorted(self.pending)))
        if self.occurred:
            parts.append("occurred=" + ",".join(sorted(self.occurred)))
        if self.automaton is not None:
            parts.append(f"automaton={self.automaton}")
        if self.clock is not None:
            parts.append(f"clock={self.clock}")
        return "; ".join(parts) or "initial"


def parse_situation(text: str) -> Situation:
    """``"pending=b2; occurred=b1; automaton=3; clock=0"`` (any of the items, event names
    separated by commas or spaces; ``pending=`` with no name: none pending); ``""`` or
    ``"initial"``: the default situation."""
    fields: dict[str, Any] = {}
    if text.strip() == "initial":
        return Situation()
    for item in filter(None, (part.strip() for part in text.split(";"))):
        key, sep, value = (s.strip() for s in item.partition("="))
        if not sep or key not in ("pending", "occurred", "automaton", "clock"):
            raise PlotError(f"situation {text!r}: {item!r} is not one of pending=EVENTS, "
                            "occurred=EVENTS, automaton=N, clock=N")
        if key in fields:
            raise PlotError(f"situation {text!r}: {key} is given twice")
        if key in ("automaton", "clock"):
            if not value.isdigit():
                raise PlotError(f"situation {text!r}: {key} must be a non-negative integer, "
                                f"got {value!r}")
            fields[key] = int(value)
        else:
            fields[key] = frozenset(filter(None, re.split(r"[,\s]+", value)))
    return Situation(**fields)


@dataclass(frozen=True, slots=True)
class CellView:
    """One cell of a policy picture: ``kind`` is ``open`` (a state with an action and a
    value), ``done`` (the task is satisfied on entering it), ``failed`` (it can no longer
    be), or ``unreached`` (the product has no such state, and entering the cell decides
    nothing); ``automaton`` is the automaton's state there."""

    kind: str
    automaton: int
    action: str | None = None
    value: float | None = None


@dataclass(frozen=True, slots=True)
class PolicyMap:
    """The policy over a grid for one situation (:func:`policy_map`)."""

    situation: Situation
    pending: frozenset[str]
    cells: Mapping[Cell, CellView]


def _grid(result: SynthesisResult) -> GridWorld:
    game = result.model.game
    if not isinstance(game, GridWorld):
        raise PlotError(f"model {result.model.name!r}: its world is a {type(game).__name__}, "
                        "not a grid; only grid worlds ([grid]) can be drawn")
    return game


def policy_map(result: SynthesisResult, situation: Situation = Situation()) -> PolicyMap:
    """The action and the value of ``result``'s policy at every cell, in ``situation``.

    The product state shown at a cell is ``(cell, q, pending, clock)`` with ``q`` the
    automaton state (stepped on the cell's letter when events ``occurred``) and the
    smallest clock the product reaches there unless the situation names one.  Values
    are the policy's exact probabilities of success in the lower model.  Raises
    :class:`PlotError` for a world that is no grid or a situation naming unknown
    events or automaton states."""
    from mitld_lp.product import ProductState

    game = _grid(result)
    mdp, dta, events = result.mdp, result.dta, result.sta.events
    for name, given in (("pending", situation.pending or frozenset()),
                        ("occurred", situation.occurred)):
        unknown = sorted(given - events)
        if unknown:
            raise PlotError(f"situation: {name}: {unknown[0]!r} is not an event of the spec "
                            f"(events: {', '.join(sorted(events)) or 'none'})")
    pending = events - situation.occurred if situation.pending is None else situation.pending
    init = mdp.states[mdp.initial]
    q0 = situation.automaton
    if q0 is None:
        if not isinstance(init, ProductState):
            raise PlotError(f"model {result.model.name!r}: the task is decided in the initial "
                            "state; there is no policy to draw")
        q0 = init.automaton
    if not 0 <= q0 < dta.n_states:
        raise PlotError(f"situation: automaton: no state {q0} (the automaton has "
                        f"{dta.n_states}: 0..{dta.n_states - 1})")
    policy, values = result.lower_model.policy, result.lower_model.policy_values
    if result.complemented:  # the complement's values, read in the task's terms
        values = 1.0 - values
    index: dict[tuple[Hashable, int, frozenset[str]], tuple[int, int]] = {}
    for i, s in enumerate(mdp.states):
        if isinstance(s, ProductState) and (situation.clock is None or
                                            s.clock == situation.clock):
            key = (s.game, s.automaton, s.pending)
            if key not in index or s.clock < index[key][0]:
                index[key] = (s.clock, i)
    cells: dict[Cell, CellView] = {}
    for cell in game.cells:
        q = dta.step(q0, game.propositions(cell) | situation.occurred) \
            if situation.occurred else q0
        if dta.is_accepting(q) or dta.is_rejecting(q):
            cells[cell] = CellView(DONE if dta.is_accepting(q) else FAILED, q)
            continue
        hit = index.get((cell, q, pending))
        if hit is None:
            # no such state; entering the cell may decide the task (a region to avoid)
            entered = dta.step(q, game.propositions(cell) | situation.occurred)
            kind = DONE if dta.is_accepting(entered) else FAILED if dta.is_rejecting(
                entered) else UNREACHED
            cells[cell] = CellView(kind, q if kind == UNREACHED else entered)
            continue
        i = hit[1]
        action = mdp.action_name(int(policy[i])) if policy[i] >= 0 else None
        cells[cell] = CellView(OPEN, q, action, float(values[i]))
    return PolicyMap(situation, pending, cells)


# --------------------------------------------------------------------------- drawing


def _figure(size: tuple[int, int]) -> Figure:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    width, height = size
    if width < 100 or height < 100 or width > 20_000 or height > 20_000:
        raise PlotError(f"size: {width}x{height} pixels; each side must be in 100..20000")
    fig = Figure(figsize=(width / _DPI, height / _DPI), dpi=_DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


_REGION_COLOURS = ("tab:red", "tab:green", "tab:orange", "tab:purple", "tab:brown",
                   "tab:pink", "tab:cyan", "tab:olive")


def draw_panel(ax: Axes, pm: PolicyMap, game: GridWorld, title: str, norm: Any) -> None:
    """One policy panel on ``ax`` (module docstring); ``norm`` maps values to colours."""
    from matplotlib import colormaps
    from matplotlib.patches import Rectangle

    cmap = colormaps["viridis"]
    colour = {name: _REGION_COLOURS[i % len(_REGION_COLOURS)]
              for i, (name, _) in enumerate(game.regions)}
    for x, y in game.obstacles:
        ax.add_patch(Rectangle((x - 0.5, y - 0.5), 1, 1, facecolor="0.1", edgecolor="white"))
    small = max(5.0, 11.0 - 0.4 * max(game.width, game.height))
    for cell, view in pm.cells.items():
        x, y = cell
        face = {DONE: "#b7e4b0", FAILED: "#f2b8b5", UNREACHED: "0.88"}.get(view.kind)
        if face is None:
            face = cmap(norm(view.value))
        ax.add_patch(Rectangle((x - 0.5, y - 0.5), 1, 1, facecolor=face, edgecolor="white",
                               linewidth=1.5))
        names = sorted(n for n in colour if cell in game.region_map[n])
        for k, name in enumerate(names):
            inset = 0.46 - 0.06 * k
            ax.add_patch(Rectangle((x - inset, y - inset), 2 * inset, 2 * inset, fill=False,
                                   edgecolor=colour[name], linewidth=2.5))
        if names:
            ax.text(x - 0.4, y + 0.4, ",".join(names), fontsize=small, fontweight="bold",
                    va="top", color=colour[names[0]])
        if cell == game.start:
            ax.text(x + 0.42, y - 0.42, "start", fontsize=small * 0.8, ha="right",
                    va="bottom", color="white" if view.kind == OPEN else "0.2")
        if view.kind != OPEN:
            ax.text(x, y, {DONE: "done", FAILED: "failed", UNREACHED: "not\nreached"}[
                view.kind], ha="center", va="center", fontsize=small * 0.85, color="0.25")
        elif view.action is not None and view.action in MOVES:
            dx, dy = MOVES[view.action]
            ax.annotate("", xy=(x + 0.3 * dx, y + 0.3 * dy), xytext=(x - 0.3 * dx, y - 0.3 * dy),
                        arrowprops={"arrowstyle": "-|>", "lw": 2, "color": "white",
                                    "mutation_scale": 14})
        elif view.action == STAY:
            ax.plot([x], [y], marker="o", color="white", markersize=8)
    ax.set_xlim(-0.5, game.width - 0.5)
    ax.set_ylim(-0.5, game.height - 0.5)
    ax.set_xticks(range(game.width))
    ax.set_yticks(range(game.height))
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)


def policy_figure(
    result: SynthesisResult,
    situations: Sequence[Situation] = (Situation(),),
    *,
    size: tuple[int, int] = DEFAULT_SIZE,
) -> Figure:
    """One panel per situation (side by side) of ``result``'s policy on its grid world,
    with a colour bar of the success probability; ``size`` in pixels."""
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    game = _grid(result)
    if not situations:
        raise PlotError("give at least one situation")
    maps = [policy_map(result, s) for s in situations]
    fig = _figure(size)
    axes = fig.subplots(1, len(maps), squeeze=False)[0]
    norm = Normalize(0.0, 1.0)
    for ax, pm in zip(axes, maps, strict=True):
        pending = ", ".join(sorted(pm.pending)) or "none"
        draw_panel(ax, pm, game, f"{pm.situation}\npending: {pending}", norm)
    fig.colorbar(ScalarMappable(norm=norm, cmap=colormaps["viridis"]), ax=list(axes),
                 shrink=0.8, label="probability of success from the cell")
    fig.suptitle(f"{result.model.name}: optimum in [{result.lower:.6f}, {result.upper:.6f}]"
                 f"{'' if result.certified else ' (NOT certified)'}", fontsize=10)
    return fig


def _column(columns: Sequence[str], name: str, what: str) -> str:
    if name in columns:
        return name
    tail = [c for c in columns if c.rsplit(".", 1)[-1] == name]
    if len(tail) == 1:
        return tail[0]
    known = ", ".join(columns)
    why = "names several columns" if tail else "is not a column"
    raise PlotError(f"{what} {name!r} {why} of the results (columns: {known})")


def _short(column: str, columns: Sequence[str]) -> str:
    """The shortest dotted tail of ``column`` that no other column ends with, at least
    two keys (``mu2.geometric``) but for a constant's name (``T``)."""
    parts = column.split(".")
    first = 1 if parts[0] == "constants" else min(2, len(parts))
    for k in range(first, len(parts) + 1):
        tail = ".".join(parts[-k:])
        if sum(1 for c in columns if c == tail or c.endswith("." + tail)) == 1:
            return tail
    return column


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def sweep_figure(
    results: str | os.PathLike[str],
    x: str,
    y: str,
    *,
    by: Iterable[str] | None = None,
    size: tuple[int, int] = DEFAULT_SIZE,
) -> Figure:
    """Column ``y`` of a sweep's results file against parameter ``x``, one line per
    combination of the ``by`` parameters (default: every other parameter that takes
    more than one value).  A column may be named by its last key (``slip`` for
    ``grid.slip``).  Points without a certified answer are drawn hollow; rows without
    a number in ``y`` are left out."""
    from mitld_lp.sweep.results import read_results
    from mitld_lp.sweep.rows import META_COLUMNS, RESULT_COLUMNS

    columns, rows, _ = read_results(results)
    parameters = [c for c in columns if c not in META_COLUMNS and c not in RESULT_COLUMNS]
    xc = _column(parameters, x, "--x")
    yc = _column(columns, y, "--y")
    if by is None:
        groups = [c for c in parameters if c != xc
                  and len({repr(r[c]) for r in rows}) > 1]
    else:
        groups = [_column(parameters, b, "--by") for b in by]
    lines: dict[str, list[tuple[Any, float, bool]]] = {}
    for r in rows:
        value = _number(r[yc])
        if value is None:
            continue
        label = ", ".join(f"{_short(g, parameters)} = {r[g]}" for g in groups)
        lines.setdefault(label, []).append((r[xc], value, bool(r["certified"])))
    if not lines:
        raise PlotError(f"{results}: no row has a number in column {yc!r}")
    numeric = all(_number(p[0]) is not None for pts in lines.values() for p in pts)
    ticks = sorted({repr(p[0]) for pts in lines.values() for p in pts})
    fig = _figure(size)
    ax = fig.subplots()
    for label, pts in sorted(lines.items()):
        pts.sort(key=lambda p: float(p[0]) if numeric else ticks.index(repr(p[0])))
        xs = [float(p[0]) if numeric else ticks.index(repr(p[0])) for p in pts]
        ys = [p[1] for p in pts]
        (line,) = ax.plot(xs, ys, marker="o", label=label or None)
        hollow = [(a, b) for a, b, (_, _, ok) in zip(xs, ys, pts, strict=True) if not ok]
        if hollow:
            ax.plot(*zip(*hollow, strict=True), linestyle="none", marker="o",
                    markerfacecolor="white", markeredgecolor=line.get_color())
    if not numeric:
        ax.set_xticks(range(len(ticks)), ticks)
    elif all(isinstance(p[0], int) for pts in lines.values() for p in pts):
        from matplotlib.ticker import MaxNLocator

        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel(xc)
    ax.set_ylabel(yc)
    ax.grid(alpha=0.3)
    if any(lines):
        ax.legend(fontsize=8)
    ax.set_title(f"{Path(results).name}: {yc} against {xc}", fontsize=10)
    return fig


def save(fig: Figure, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
    """Write ``fig`` to ``path`` (``.png``, ``.svg`` or ``.pdf``) at its own size, under
    the package's rule for output files (:mod:`mitld_lp.files.write`: an existing file is
    replaced only with ``overwrite``, and only once the new one is complete; a path the
    rule refuses raises :class:`~mitld_lp.files.write.OutputPathError`)."""
    return files.write_figure(fig, path, overwrite=overwrite, suffixes=FIGURE_SUFFIXES,
                              dpi=_DPI)


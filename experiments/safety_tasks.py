"""Tasks with a safety part: the bus task with ``G !puddle`` and the patrol with a no-go
zone, beside their co-safe versions, each checked by Storm on the exported product.

For each model: our certified bracket, Storm's ``Pmax=? [F "accept"]`` on the DRN export
(the label marks the accepting end components), the seconds of each (wall and CPU) and
their ratio.  A figure draws the bus-with-puddles policy on the grid: the first panel
while both buses are awaited, the second the actions that keep the robot dry for ever
once a bus is caught (the accepting end components: never an action that can leave them).

Run: ``python experiments/safety_tasks.py [--quick] [--out DIR]``.  ``--quick`` leaves
out the patrol models.  Writes ``safety_tasks.md`` and ``safety_policy.png``.
"""

from __future__ import annotations

import time
from collections.abc import Hashable
from dataclasses import dataclass
from pathlib import Path

import _common as C
import matplotlib.pyplot as plt
from matplotlib.colors import Normalize
from matplotlib.patches import Rectangle

import mitld_lp
from mitld_lp.product import ProductState
from mitld_lp.solvers.iteration import evaluate_policy
from mitld_lp.worlds.grid import MOVES

PAIRS = (("bus_grid.toml", "bus_puddle.toml"), ("patrol.toml", "patrol_nogo.toml"))


@dataclass(frozen=True)
class Row:
    model: str
    spec_class: str
    lower: float
    upper: float
    certified: bool
    storm: float | None
    seconds: float
    cpu: float
    storm_seconds: float | None


def storm_value(result: mitld_lp.SynthesisResult) -> tuple[float | None, float | None]:
    """Storm's Pmax=? [F "accept"] on the lower model's DRN export, and its seconds."""
    return C.storm_pmax(result.mdp, result.acceptance.goal)


def solve(name: str) -> tuple[Row, mitld_lp.SynthesisResult]:
    model = mitld_lp.load_model(C.model_path(name))
    t0, c0 = time.perf_counter(), time.process_time()
    r = mitld_lp.synthesize(model)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    storm, storm_s = storm_value(r)
    return Row(model.name, r.dta.fragment, r.lower, r.upper, r.certified, storm, wall, cpu,
               storm_s), r


def panels(result: mitld_lp.SynthesisResult, game) -> list[tuple[str, dict, dict]]:
    """(title, action per cell, value per cell): while both buses are awaited (the
    initial automaton state read on each cell, the smallest clock), and inside the
    accepting end components (any of their states on the cell)."""
    mdp, dta = result.mdp, result.dta
    goal = result.acceptance.goal
    values = evaluate_policy(mdp, goal, result.lower_model.policy)
    q0 = dta.initial
    start: dict[Hashable, tuple[int, int]] = {}
    keep: dict[Hashable, int] = {}
    for i, s in enumerate(mdp.states):
        if not isinstance(s, ProductState):
            continue
        if goal[i]:
            keep.setdefault(s.game, i)
        elif s.pending == result.sta.events and s.automaton == dta.step(
                q0, game.propositions(s.game)):
            if s.game not in start or s.clock < start[s.game][0]:
                start[s.game] = (s.clock, i)
    out = []
    for title, index in (("waiting for both buses", {c: i for c, (_, i) in start.items()}),
                         ("bus caught: keeping dry for ever", keep)):
        acts = {c: mdp.action_name(int(result.lower_model.policy[i])) for c, i in index.items()
                if result.lower_model.policy[i] >= 0}
        vals = {c: float(values[i]) for c, i in index.items()}
        out.append((title, acts, vals))
    return out


def figure(result: mitld_lp.SynthesisResult, path: Path) -> Path:
    game = result.model.game
    width = max(c[0] for c in game.cells) + 1
    height = max(c[1] for c in game.cells) + 1
    fig, axes = plt.subplots(1, 2, figsize=(9, 4.6))
    norm = Normalize(0, 1)
    cmap = plt.get_cmap("viridis")
    regions = game.region_map
    for ax, (title, acts, vals) in zip(axes, panels(result, game), strict=True):
        for cell in game.cells:
            x, y = cell
            v = vals.get(cell)
            ax.add_patch(Rectangle((x - 0.5, y - 0.5), 1, 1, edgecolor="white", linewidth=2,
                                   facecolor=cmap(norm(v)) if v is not None else "0.85"))
            if cell in regions.get("puddle", ()):
                ax.add_patch(Rectangle((x - 0.5, y - 0.5), 1, 1, facecolor="tab:blue",
                                       hatch="//", edgecolor="white", linewidth=2))
                ax.text(x, y, "puddle", ha="center", va="center", color="white", fontsize=8)
                continue
            for name in ("A", "B"):
                if cell in regions.get(name, ()):
                    ax.text(x - 0.4, y + 0.38, name, fontsize=12, fontweight="bold",
                            va="top", color="tab:red")
            a = acts.get(cell)
            if a is not None:
                dx, dy = MOVES[a]
                ax.annotate("", xy=(x + 0.3 * dx, y + 0.3 * dy),
                            xytext=(x - 0.3 * dx, y - 0.3 * dy),
                            arrowprops=dict(arrowstyle="-|>", lw=2.2, color="white",
                                            mutation_scale=18))
        ax.set_xlim(-0.5, width - 0.5)
        ax.set_ylim(-0.5, height - 0.5)
        ax.set_xticks(range(width))
        ax.set_yticks(range(height))
        ax.set_aspect("equal")
        ax.set_title(title, fontsize=10)
    fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=list(axes),
                 label="P(task kept) under the policy")
    fig.suptitle(f"{result.model.spec_text}\noptimum in [{result.lower:.4f}, "
                 f"{result.upper:.4f}]", fontsize=9)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> list[Row]:
    args = C.parser(__doc__.splitlines()[0]).parse_args(argv)
    out = C.out_dir(args)
    names = [n for pair in (PAIRS[:1] if args.quick else PAIRS) for n in pair]
    rows: list[Row] = []
    puddle = None
    for name in names:
        row, r = solve(name)
        rows.append(row)
        if name == "bus_puddle.toml":
            puddle = r
    lines = ["| model | class | lower | upper | certified | Storm on the DRN | |diff| "
             "| seconds (wall / CPU) | Storm s | ratio |", "|" + "---|" * 10]
    for r in rows:
        diff = abs(r.storm - r.lower) if r.storm is not None else float("nan")
        ratio = r.seconds / r.storm_seconds if r.storm_seconds else float("nan")
        lines.append(
            f"| {r.model} | {r.spec_class} | {r.lower:.7f} | {r.upper:.7f} | {r.certified} "
            f"| {r.storm if r.storm is not None else 'n/a'} | {diff:.1e} "
            f"| {r.seconds:.2f} / {r.cpu:.2f} | "
            f"{r.storm_seconds if r.storm_seconds is not None else float('nan'):.3f} "
            f"| {ratio:.1f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    print("Storm solves only the exported product (it has no event laws): the ratio "
          "compares our whole pipeline with its model checking of that product.")
    C.write_text(out / "safety_tasks.md", text)
    if puddle is not None:
        print(f"wrote {figure(puddle, out / 'safety_policy.png')}")
    return rows


if __name__ == "__main__":
    main()

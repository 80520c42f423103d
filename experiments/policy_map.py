"""The synthesised policy of the bus-catching case study, drawn on the 4x4 grid.

One panel per main situation of the automaton and the events: waiting for both buses
(the initial automaton location, pending {b1, b2}); bus 1 just arrived (the automaton
state the DTA reaches from its initial state on a letter with b1, pending {b2}); bus 2
just arrived (likewise with b2, pending {b1}).  In each, an arrow per cell shows the
deterministic policy's action and the cell's colour the probability of success from
there.  The product states are found by decoding ``mdp.states`` and stepping the DTA,
never by index.  Then one sampled run (fixed seed) is printed in the paper's notation.

Run: ``python experiments/policy_map.py [--quick] [--out DIR] [--seed N]``.
Writes ``policy_map.png``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Hashable
from dataclasses import dataclass

import _common as C
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import Normalize
from matplotlib.patches import Rectangle

import mitld_lp
from mitld_lp.gridworld import MOVES
from mitld_lp.product import ProductState
from mitld_lp.simulate import rollout

MODELS = (("case 1", "bus_grid.toml"), ("case 2", "bus_grid_case2.toml"))
STATION_COLOURS = {"A": "tab:red", "B": "tab:green"}


@dataclass(frozen=True)
class Panel:
    title: str
    automaton: dict[Hashable, int | None]  # per cell: DTA state, None if decided there
    pending: frozenset[str]
    actions: dict[Hashable, str]  # per cell: the policy's action
    values: dict[Hashable, float]  # per cell: success probability under the policy


def situations(result: mitld_lp.SynthesisResult, game) -> list[Panel]:
    """The three panels, found by decoding the product's states."""
    mdp, dta, sta = result.mdp, result.dta, result.sta
    init = mdp.states[mdp.initial]
    assert isinstance(init, ProductState), "the initial state is already decided"
    q0, events = init.automaton, sta.events
    policy, values = result.lower_model.policy, result.lower_model.policy_values
    # index: (cell, automaton state, pending) -> the state with the smallest clock
    # (the one entered right after the situation arises)
    index: dict[tuple[Hashable, int, frozenset[str]], tuple[int, int]] = {}
    for i, s in enumerate(mdp.states):
        if isinstance(s, ProductState):
            key = (s.game, s.automaton, s.pending)
            if key not in index or s.clock < index[key][0]:
                index[key] = (s.clock, i)

    def panel(title: str, occurred: frozenset[str]) -> Panel:
        pending = events - occurred
        autom: dict[Hashable, int | None] = {}
        actions: dict[Hashable, str] = {}
        vals: dict[Hashable, float] = {}
        for cell in game.cells:
            # the DTA reads the cell's propositions together with the events just seen
            q = dta.step(q0, game.propositions(cell) | occurred) if occurred else q0
            if q in (dta.accepting, dta.rejecting):
                autom[cell] = None
                continue
            autom[cell] = q
            hit = index.get((cell, q, pending))
            if hit is None:  # not reachable in this situation
                continue
            i = hit[1]
            vals[cell] = float(values[i])
            if policy[i] >= 0:
                actions[cell] = mdp.action_name(int(policy[i]))
        return Panel(title, autom, pending, actions, vals)

    b1, b2 = sorted(events)
    return [
        panel(f"waiting for both buses\npending {{{b1}, {b2}}}", frozenset()),
        panel(f"bus 1 ({b1}) just arrived\npending {{{b2}}}", frozenset({b1})),
        panel(f"bus 2 ({b2}) just arrived\npending {{{b1}}}", frozenset({b2})),
    ]


def draw(ax, panel: Panel, game, dta, norm) -> None:
    width = max(c[0] for c in game.cells) + 1
    height = max(c[1] for c in game.cells) + 1
    cmap = plt.get_cmap("viridis")
    regions = game.region_map
    for cell in game.cells:
        x, y = cell
        v = panel.values.get(cell)
        face = cmap(norm(v)) if v is not None else "0.85"
        ax.add_patch(Rectangle((x - 0.5, y - 0.5), 1, 1, facecolor=face, edgecolor="white",
                               linewidth=2))
        for name, cells in regions.items():
            if cell in cells:
                ax.add_patch(Rectangle((x - 0.46, y - 0.46), 0.92, 0.92, fill=False,
                                       edgecolor=STATION_COLOURS.get(name, "k"), linewidth=3))
                ax.text(x - 0.4, y + 0.38, name, fontsize=12, fontweight="bold", va="top",
                        color=STATION_COLOURS.get(name, "k"))
        if cell == game.initial:
            ax.text(x + 0.4, y - 0.4, "start", fontsize=7, ha="right", va="bottom",
                    color="white")
        if panel.automaton.get(cell) is None:
            ax.text(x, y, "caught", ha="center", va="center", fontsize=8, color="k")
            continue
        a = panel.actions.get(cell)
        if a is not None:
            dx, dy = MOVES[a]
            ax.annotate("", xy=(x + 0.32 * dx, y + 0.32 * dy),
                        xytext=(x - 0.32 * dx, y - 0.32 * dy),
                        arrowprops=dict(arrowstyle="-|>", lw=2.2, color="white",
                                        mutation_scale=18))
            ax.text(x + 0.42, y + 0.42, a, fontsize=7, ha="right", va="top", color="white")
        elif panel.values.get(cell) is None:
            ax.text(x, y, "not\nreached", ha="center", va="center", fontsize=7,
                    color="0.3")
    ax.set_xlim(-0.5, width - 0.5)
    ax.set_ylim(-0.5, height - 0.5)
    ax.set_xticks(range(width))
    ax.set_yticks(range(height))
    ax.set_xlabel("x (E is +x)")
    ax.set_ylabel("y (N is +y)")
    ax.set_aspect("equal")
    qs = {q for q in panel.automaton.values() if q is not None}
    loc = ", ".join(
        f"q{q}" + (" [" + ", ".join(f"{n}: x={v}" for n, v in dta.clocks(q)) + "]"
                   if dta.clocks(q) else "")
        for q in sorted(qs))
    ax.set_title(f"{panel.title}\nautomaton {loc}", fontsize=9)


def _set(s: frozenset[str]) -> str:
    return "{" + ", ".join(sorted(s)) + "}" if s else "{}"


def trajectory(result: mitld_lp.SynthesisResult, seed: int) -> list[str]:
    """One sampled run in the paper's notation: ((x, y), events, pending), (location,
    clocks) and the action taken."""
    dta = result.dta
    status, steps = rollout(result.model, result.controller, np.random.default_rng(seed),
                            max_steps=100, record=True)
    lines = []
    used: set[int] = set()
    shown = steps if len(steps) <= 14 else steps[:12]
    for st in shown:
        clocks = ", ".join(f"{n}: x={v}" for n, v in dta.clocks(st.automaton))
        used.add(st.automaton)
        verdict = (" accept" if dta.is_accepting(st.automaton) else
                   " reject" if dta.is_rejecting(st.automaton) else "")
        act = f"--{st.action}-->" if st.action is not None else f"=> {status.value}"
        lines.append(f"  t={st.t:<2} (({st.state}, {_set(st.events)}, {_set(st.pending)}), "
                     f"(q{st.automaton}{verdict}, ({clocks})))  {act}")
    if len(shown) < len(steps):
        lines.append(f"  ... {len(steps) - len(shown)} more steps => {status.value}")
    lines.append("  where")
    for q in sorted(used):
        text = "accept (true)" if dta.is_accepting(q) else dta.location(q)
        lines.append(f"    q{q} = {text}")
    return lines


def main(argv: list[str] | None = None) -> list[list[Panel]]:
    ap = C.parser(__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0, help="seed of the sampled run")
    args = ap.parse_args(argv)
    out = C.out_dir(args)
    start = time.perf_counter()
    cases = MODELS[:1] if args.quick else MODELS
    fig, axes = plt.subplots(len(cases), 3, figsize=(13, 4.9 * len(cases)),
                             squeeze=False, constrained_layout=True)
    solved = {}
    for case, model_file in MODELS:
        model = mitld_lp.load_model(C.model_path(model_file))
        result = mitld_lp.synthesize(model)
        assert result.certified, result.failed_checks
        solved[case] = (model, result, situations(result, model.game))
    lowest = min(v for case, _ in cases for p in solved[case][2] for v in p.values.values())
    norm = Normalize(math.floor(lowest * 10) / 10, 1.0)
    all_panels = []
    for row, (case, model_file) in zip(axes, cases, strict=True):
        model, result, panels = solved[case]
        game = model.game
        all_panels.append(panels)
        laws = ", ".join(f"{a} ~ {d}" for a, d in sorted(model.distributions.items()))
        print(f"{case} ({model_file}: {laws}): optimum {result.lower:.7f}")
        print("  policy per cell (x, y):action in each situation")
        for ax, panel in zip(row, panels, strict=True):
            draw(ax, panel, game, result.dta, norm)
            name = panel.title.splitlines()[0]
            acts = " ".join(f"{c}:{panel.actions[c]}" for c in sorted(panel.actions))
            print(f"  {name}: {acts}")
        row[0].text(-0.32, 0.5, f"{case}\n{laws}", transform=row[0].transAxes, rotation=90,
                    ha="center", va="center", fontsize=11, fontweight="bold")
    # the paper's sample run is of case 2; so is ours
    case, _ = MODELS[-1]
    model, result, _ = solved[case]
    print(f"A sampled run of {case} (seed {args.seed}), in the paper's notation (Sec. V):")
    print("  t  ((cell, events of the last step, pending events), (automaton state, "
          "deadline clocks))  action")
    print("\n".join(trajectory(result, args.seed)))
    print()
    sm = plt.cm.ScalarMappable(norm=norm, cmap="viridis")
    fig.colorbar(sm, ax=axes, shrink=0.8, label="probability of success from the cell "
                 "(policy's exact value)")
    fig.suptitle("Optimal policy of the bus-catching task: arrow = action of the deterministic"
                 " policy; 'caught' = the task is satisfied on arrival there", fontsize=12)
    png = out / "policy_map.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
    print(f"wrote {C.shown(png)} ({time.perf_counter() - start:.1f} s)")
    return all_panels


if __name__ == "__main__":
    main()

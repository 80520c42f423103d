"""The synthesised policy of the bus-catching case study, drawn on the 4x4 grid.

One panel per main situation of the automaton and the events: waiting for both buses
(the initial automaton location, pending {b1, b2}); bus 1 just arrived (the automaton
state the DTA reaches from its initial state on a letter with b1, pending {b2}); bus 2
just arrived (likewise with b2, pending {b1}).  In each, an arrow per cell shows the
deterministic policy's action and the cell's colour the probability of success from
there.  The panels are the library's (``mitld_lp.plot.policy_map``: product states
found by decoding ``mdp.states`` and stepping the DTA, never by index; ``mitld-lp plot``
draws the same for any grid world).  Then one sampled run (fixed seed) is printed in
the paper's notation.

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

import mitld_lp
from mitld_lp.plot import PolicyMap, Situation, draw_panel, policy_map
from mitld_lp.running.simulate import rollout

MODELS = (("case 1", "bus_grid.toml"), ("case 2", "bus_grid_case2.toml"))


@dataclass(frozen=True)
class Panel:
    title: str
    automaton: dict[Hashable, int | None]  # per cell: DTA state, None if decided there
    pending: frozenset[str]
    actions: dict[Hashable, str]  # per cell: the policy's action
    values: dict[Hashable, float]  # per cell: success probability under the policy
    map: PolicyMap  # the library's view of the situation, which the panel draws


def situations(result: mitld_lp.SynthesisResult) -> list[Panel]:
    """The three panels, from the library's policy map of each situation."""
    events = result.sta.events
    b1, b2 = sorted(events)

    def panel(title: str, occurred: frozenset[str]) -> Panel:
        pm = policy_map(result, Situation(occurred=occurred))
        live = {c: v for c, v in pm.cells.items() if v.kind in ("open", "unreached")}
        return Panel(
            title,
            {c: (v.automaton if c in live else None) for c, v in pm.cells.items()},
            pm.pending,
            {c: v.action for c, v in live.items() if v.action is not None},
            {c: v.value for c, v in live.items() if v.value is not None},
            pm,
        )

    return [
        panel(f"waiting for both buses\npending {{{b1}, {b2}}}", frozenset()),
        panel(f"bus 1 ({b1}) just arrived\npending {{{b2}}}", frozenset({b1})),
        panel(f"bus 2 ({b2}) just arrived\npending {{{b1}}}", frozenset({b2})),
    ]


def draw(ax, result: mitld_lp.SynthesisResult, panel: Panel, norm) -> None:
    """The library's panel, titled with the situation and its automaton locations."""
    dta = result.dta
    qs = {q for q in panel.automaton.values() if q is not None}
    loc = ", ".join(
        f"q{q}" + (" [" + ", ".join(f"{n}: x={v}" for n, v in dta.clocks(q)) + "]"
                   if dta.clocks(q) else "")
        for q in sorted(qs))
    draw_panel(ax, panel.map, result.model.game, f"{panel.title}\nautomaton {loc}", norm)


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
        solved[case] = (model, result, situations(result))
    lowest = min(v for case, _ in cases for p in solved[case][2] for v in p.values.values())
    norm = Normalize(math.floor(lowest * 10) / 10, 1.0)
    all_panels = []
    for row, (case, model_file) in zip(axes, cases, strict=True):
        model, result, panels = solved[case]
        all_panels.append(panels)
        laws = ", ".join(f"{a} ~ {d}" for a, d in sorted(model.distributions.items()))
        print(f"{case} ({model_file}: {laws}): optimum {result.lower:.7f}")
        print("  policy per cell (x, y):action in each situation")
        for ax, panel in zip(row, panels, strict=True):
            draw(ax, result, panel, norm)
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
                 " policy; 'done' = the task is satisfied on arrival there", fontsize=12)
    png = out / "policy_map.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
    print(f"wrote {C.shown(png)} ({time.perf_counter() - start:.1f} s)")
    return all_panels


if __name__ == "__main__":
    main()

"""Benchmark: one big strongly connected block, where the topological order cannot help.

A ``n x n`` grid (slip 0.1) with 20% random holes and the task ``!H U A`` (reach the far
corner without falling into a hole): after the reduction the whole reachable grid is one
block, so the default route solves one large occupancy LP with Clarabel.  Compared in one
run with HiGHS (simplex, through cvxpy) on the same LP, and with interval iteration.

    python experiments/bench_big_component.py            # n = 150 (18k-state block)
    python experiments/bench_big_component.py --quick    # n = 40, into experiments/out/quick
"""

from __future__ import annotations

import time

import numpy as np
from _common import markdown_table, out_dir, parser, text_table, write_text

from mitld_lp import GridWorld, Model
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.quotient import reduce
from mitld_lp.solvers.topological import blocks
from mitld_lp.synthesis import build_product

HEADER = ("route", "seconds", "value", "status", "ratio to HiGHS")


def main(argv: list[str] | None = None) -> list[tuple[object, ...]]:
    ap = parser(__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=None, help="grid size (default 150, quick 40)")
    ap.add_argument("--ii-budget", type=float, default=60.0,
                    help="seconds for interval iteration (status time_limit past it)")
    args = ap.parse_args(argv)
    n = args.n or (40 if args.quick else 150)
    rng = np.random.default_rng(0)
    holes = [(x, y) for x in range(n) for y in range(n)
             if rng.random() < 0.2 and (x, y) not in ((0, 0), (n - 1, n - 1))]
    world = GridWorld.make(n, n, start=(0, 0), slip=0.1,
                           regions={"A": [(n - 1, n - 1)], "H": holes})
    model = Model.from_game(world, "!H U A")
    mdp = build_product(model.game, model.spec, model.distributions).mdp
    q = reduce(mdp, mdp.target)
    size = int(blocks(q).size.max()) if q.n_states else 0
    print(f"{n}x{n} grid: {mdp.n_states} states, {q.n_states} reduced, largest block {size}")
    runs = []
    for label, kw in (("Clarabel, block by block (default)", {}),
                      ("HiGHS via cvxpy, monolithic", {"solver": "HIGHS", "layout": "whole"})):
        t = time.perf_counter()
        r = solve_lp(mdp, mdp.target, quotient=q, **kw)  # type: ignore[arg-type]
        runs.append((label, time.perf_counter() - t, r.value, r.status.value))
    t = time.perf_counter()
    it = interval_iteration(mdp, mdp.target, quotient=q, progress=False,
                            time_limit=args.ii_budget)
    runs.append(("interval iteration (lower bound)", time.perf_counter() - t, it.value_lower,
                 it.status.value))
    highs = runs[1][1]
    rows = [(label, f"{s:.3f}", f"{v:.10f}", status, f"{s / highs:.3g}")
            for label, s, v, status in runs]
    print(text_table(HEADER, rows))
    out = out_dir(args)
    write_text(out / "bench_big_component.md",
               f"{n}x{n} grid, {mdp.n_states} states, largest block {size}\n\n"
               + markdown_table(HEADER, rows))
    return rows


if __name__ == "__main__":
    main()

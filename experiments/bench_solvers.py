"""Benchmark: the solvers on the same MDPs, block by block against the monolithic LP.

Models: the bus family of the README (an n x n grid, two geometric buses, stations A
and B, deadline 3) for n = 16, 32, 64, and a random MDP with local successors (long
chains, many small end components).  Each row solves the lower model (quotient built
once per model, outside the timings) by

* ``topo``: the default LP route, block by block in topological order (direct Clarabel),
* ``topo-cvx``: the same through cvxpy + Clarabel (what ``synthesize`` runs),
* ``mono``: the one monolithic LP, direct Clarabel (the route before issue 9),
* ``highs``: the monolithic LP through cvxpy + HiGHS (the peer),
* ``ii``: interval iteration in topological order, ``ii-flat``: the plain sweeps,

and prints seconds, the ratio of each route to ``topo``, and the largest difference of
the values at the initial state.  A route is skipped (printed ``skip``) on models above
its state budget (``--mono-max``, default 30,000 reduced states: the monolithic Clarabel
LP takes minutes beyond).  Tests never time anything; the figures are printed here.

Run: ``python experiments/bench_solvers.py [--quick] [--sizes 16 32 64] [--out DIR]``.
``--quick`` (small sizes) writes to a scratch folder, never over committed results.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from _common import markdown_table, out_dir, parser, shown, text_table, write_text

from mitld_lp import GridWorld, Model
from mitld_lp.mdp import MDP
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.quotient import reduce
from mitld_lp.synthesis import build_product
from mitld_lp.testing import random_mdp

SPEC = ("(D[geometric(0.8)] b1 & F(b1 & F[0,3] A)) | "
        "(D[geometric(0.3)] b2 & F(b2 & F[0,3] B))")
ROUTES = ("topo", "topo-cvx", "mono", "highs", "ii", "ii-flat")


def bus_mdp(n: int) -> MDP:
    world = GridWorld.make(n, n, start=(0, 0), slip=0.1,
                           regions={"A": [(1, 2)], "B": [(3, 0)]})
    model = Model.from_game(world, SPEC)
    return build_product(model.game, model.spec, model.distributions,
                         epsilon=model.epsilon, progress=False).mdp


def undecided(mdp: MDP) -> MDP:
    """``mdp`` started in its first state that is neither target nor prob-0 (a random
    MDP's state 0 may be decided by the graph analysis, which would time nothing)."""
    q = reduce(mdp, mdp.target)
    return replace(mdp, initial=int(np.flatnonzero(q.state_map >= 0)[0]))


def timed(fn: Callable[[], Any]) -> tuple[Any, float]:
    t = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t


def run_model(name: str, mdp: MDP, mono_max: int) -> list[object]:
    q = reduce(mdp, mdp.target)
    t = mdp.target
    calls: dict[str, Callable[[], Any]] = {
        "topo": lambda: solve_lp(mdp, t, quotient=q, backend="direct"),
        "topo-cvx": lambda: solve_lp(mdp, t, quotient=q),
        "mono": lambda: solve_lp(mdp, t, quotient=q, backend="direct", layout="whole"),
        "highs": lambda: solve_lp(mdp, t, quotient=q, solver="HIGHS", layout="whole"),
        "ii": lambda: interval_iteration(mdp, t, quotient=q, progress=False),
        "ii-flat": lambda: interval_iteration(mdp, t, quotient=q, progress=False,
                                              topological=False),
    }
    seconds: dict[str, float] = {}
    values: list[float] = []
    flags: dict[str, str] = {}
    for route in ROUTES:
        if route == "mono" and q.n_states > mono_max:
            continue
        res, secs = timed(calls[route])
        seconds[route] = secs
        ok = res.status.value == "optimal"
        flags[route] = "" if ok else "!"
        if route.startswith("ii"):
            values += [res.value_lower, res.value_upper]
        elif ok:
            values.append(res.value)
    base = seconds["topo"]
    cells: list[object] = [name, f"{mdp.n_states:,}", f"{q.n_states:,}"]
    for route in ROUTES:
        if route not in seconds:
            cells.append(f"skip (> {mono_max:,})")
            continue
        ratio = "" if route == "topo" else f" ({seconds[route] / base:.1f}x)"
        cells.append(f"{seconds[route]:.2f}{flags[route]}{ratio}")
    cells += [f"{values[0]:.9f}", f"{max(values) - min(values):.1e}"]
    print(text_table(HEADER, [cells]).splitlines()[-1], flush=True)
    return cells


HEADER = ("model", "states", "reduced", *(f"{r} s" for r in ROUTES), "value", "max diff")


def main(argv: list[str] | None = None) -> None:
    ap = parser(__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=None,
                    help="grid sizes n of the bus family (default 16 32 64)")
    ap.add_argument("--random-states", type=int, default=None,
                    help="states of the random local MDP (default 100,000)")
    ap.add_argument("--mono-max", type=int, default=30_000,
                    help="skip the monolithic Clarabel LP above this many reduced states")
    args = ap.parse_args(argv)
    sizes = args.sizes or ([4, 8] if args.quick else [16, 32, 64])
    n_random = args.random_states or (2_000 if args.quick else 100_000)
    out = out_dir(args)
    print(text_table(HEADER, []).splitlines()[0])
    rows = [run_model(f"bus {n}x{n}", bus_mdp(n), args.mono_max) for n in sizes]
    rows.append(run_model(f"random local {n_random:,}",
                          undecided(random_mdp(n_random, seed=1, locality=8,
                                               self_loop_fraction=0.2)),
                          args.mono_max))
    print("\n'!' marks a status other than optimal; (Nx) is the time over 'topo'.")
    path = write_text(out / "bench_solvers.md", markdown_table(HEADER, rows))
    print(f"wrote {shown(path)}")


if __name__ == "__main__":
    main()

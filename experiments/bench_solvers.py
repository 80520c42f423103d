"""Benchmark: the solvers on the same product MDPs of growing size.

For grid worlds of growing size (products of about 1e3 to 1e5 states; two buses, one
geometric and one with a pmf arrival time, deadlines of 3 steps) each row solves the
lower model by

* the occupancy LP through cvxpy with Clarabel,
* the same LP by a direct Clarabel call on the sparse matrices (no cvxpy),
* the same LP through cvxpy with HiGHS,
* interval iteration (tolerance 1e-9),

and prints the seconds of each, the value each reports at the initial state, and the
largest difference between them.  Also: the canonical model end to end in-process
(``synthesize`` on models/bus_grid.toml, warm).

Targets (issue 5): canonical end to end < 0.5 s; at 1e5 states interval iteration
< 5 s, direct Clarabel < 60 s, cvxpy+Clarabel within 2x of direct Clarabel.

Run: ``python experiments/bench_solvers.py [--sizes 6 20 64 150] [--skip-cvxpy-above N]``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from mitld_lp import GridWorld, load_model, synthesize
from mitld_lp.automata.sta import make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.logic.parser import parse
from mitld_lp.model import bind_distributions
from mitld_lp.product import product
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp

SPEC = ("(D[geometric(0.3)] b1 & F(b1 & F[0,3] A)) | "
        "(D[pmf(0.1, 0.2, 0.3, 0.2, 0.2)] b2 & F(b2 & F[0,3] B))")
MODELS = Path(__file__).resolve().parent.parent / "models"


def grid_mdp(n: int):
    world = GridWorld.make(n, n, start=(0, 0), slip=0.1,
                           regions={"A": [(1, 2)], "B": [(min(3, n - 1), 0)]})
    spec = parse(SPEC)
    sta = make_sta(to_dta(spec), bind_distributions(spec), 0.01)
    return product(world, sta, progress=False)


def timed(fn, *args, **kwargs):
    t = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[6, 20, 64, 150])
    ap.add_argument("--skip-cvxpy-above", type=int, default=200_000,
                    help="skip the cvxpy rows for larger products")
    args = ap.parse_args(argv)

    model = load_model(MODELS / "bus_grid.toml")
    synthesize(model)  # warm: imports, caches
    r, secs = timed(synthesize, model)
    print(f"canonical model end to end (warm): {secs:.3f} s, value {r.value:.7f}, "
          f"certified {r.certified}")
    print()
    header = (f"{'grid':>6} {'states':>9} {'trans':>10} | {'cvxpy+Clar':>10} {'Clarabel':>9} "
              f"{'cvxpy+HiGHS':>11} {'interval':>9} | {'value':>10} {'max diff':>9}")
    print(header)
    for n in args.sizes:
        mdp = grid_mdp(n)
        t = mdp.target
        rows = {}
        if mdp.n_states <= args.skip_cvxpy_above:
            rows["cvxpy+Clar"] = timed(solve_lp, mdp, t, solver="CLARABEL")
        rows["Clarabel"] = timed(solve_lp, mdp, t, backend="direct")
        if mdp.n_states <= args.skip_cvxpy_above:
            rows["cvxpy+HiGHS"] = timed(solve_lp, mdp, t, solver="HIGHS")
        it, it_s = timed(interval_iteration, mdp, t, progress=False)
        values = [res.value for res, _ in rows.values()] + [it.value_lower, it.value_upper]
        cells = []
        for name in ("cvxpy+Clar", "Clarabel", "cvxpy+HiGHS"):
            if name in rows:
                res, s = rows[name]
                cells.append(f"{s:>{len(name) if len(name) > 9 else 9}.2f}"
                             + ("" if res.status.value == "optimal" else "!"))
            else:
                cells.append(f"{'-':>{len(name) if len(name) > 9 else 9}}")
        print(f"{n:>3}x{n:<2} {mdp.n_states:>9,} {mdp.n_transitions:>10,} | "
              f"{cells[0]:>10} {cells[1]:>9} {cells[2]:>11} {it_s:>9.2f} | "
              f"{it.value_lower:>10.7f} {max(values) - min(values):>9.1e}")
    print("\n'!' marks a solver status other than optimal.")


if __name__ == "__main__":
    main()

"""Benchmark: product construction throughput and memory on growing grids.

Each row: an n x n grid (n = 8 .. 64) with three events -- one memoryless
(geometric), two not (pmf and Poisson, the latter truncated) -- and a task with a
deadline (``--deadline``, default 4) after each event at a region in a different
corner.  Printed: reachable
states, transitions, seconds, transitions per second, and peak memory per
transition (tracemalloc's peak during the build, divided by the transitions).

Targets (issue 4): >= 200k transitions/s and <= 150 bytes per transition.

Run: ``python experiments/bench_product.py [--sizes 8 16 32 64]``.
"""

from __future__ import annotations

import argparse
import time
import tracemalloc

from mitld_lp.automata.sta import make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.gridworld import GridWorld
from mitld_lp.logic.parser import parse
from mitld_lp.model import bind_distributions
from mitld_lp.product import product

SPEC = (
    "D[geometric(0.2)] a & D[pmf(0.1, 0.2, 0.3, 0.4)] b & D[poisson(3.0)] c"
    " & F(a & F[0,{d}] A) & F(b & F[0,{d}] B) & F(c & F[0,{d}] C)"
)


def world(n: int) -> GridWorld:
    return GridWorld.make(
        n, n, start=(n // 2, n // 2), slip=0.1,
        regions={"A": [(0, 0)], "B": [(n - 1, 0)], "C": [(0, n - 1)]},
    )


def build(
    n: int, deadline: int, epsilon: float, measure_memory: bool
) -> tuple[int, int, float, float]:
    spec = parse(SPEC.format(d=deadline))
    sta = make_sta(to_dta(spec), bind_distributions(spec), epsilon)
    game = world(n)
    if measure_memory:
        tracemalloc.start()
    t = time.perf_counter()
    mdp = product(game, sta, progress=False)
    seconds = time.perf_counter() - t
    peak = 0.0
    if measure_memory:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    return mdp.n_states, mdp.n_transitions, seconds, peak


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[8, 16, 32, 64])
    ap.add_argument("--epsilon", type=float, default=0.01)
    ap.add_argument("--deadline", type=int, default=4, help="steps allowed after each event")
    ap.add_argument("--no-memory", action="store_true",
                    help="skip tracemalloc (it slows the build down about 2x)")
    args = ap.parse_args(argv)
    print(f"{'grid':>6} {'states':>10} {'transitions':>12} {'seconds':>8} "
          f"{'trans/s':>10} {'bytes/trans':>12}")
    for n in args.sizes:
        states, trans, seconds, _ = build(n, args.deadline, args.epsilon, False)
        per = float("nan")
        if not args.no_memory:
            _, _, _, peak = build(n, args.deadline, args.epsilon, True)
            per = peak / trans
        print(f"{n:>3}x{n:<2} {states:>10,} {trans:>12,} {seconds:>8.2f} "
              f"{trans / seconds:>10,.0f} {per:>12.0f}")


if __name__ == "__main__":
    main()

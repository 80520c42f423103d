"""How fast the DRN export is written, beside Storm reading the same file.

The bus task (``models/bus_grid.toml``'s formula and laws) on n x n grids; for each the
product is built once, then ``write_drn`` writes it (CPU and wall seconds, transitions
per CPU second) and Storm parses the file (``stormpy.build_model_from_drn``, CPU seconds):
the ratio says how our writer compares with the peer's reader on the same bytes.
Written: ``bench_drn.csv``.
"""

from __future__ import annotations

import sys
import time

import _common
import stormpy

from mitld_lp import Model, load_model
from mitld_lp.distributions import geometric
from mitld_lp.solvers.export import write_drn
from mitld_lp.synthesis import build_product
from mitld_lp.worlds.grid import GridWorld


def _timed(fn, *args, **kwargs):
    w, c = time.perf_counter(), time.process_time()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - w, time.process_time() - c


def main(argv: list[str] | None = None):
    args = _common.parser(__doc__.splitlines()[0]).parse_args(argv)
    out = _common.out_dir(args)
    sizes = [8, 16] if args.quick else [32, 64, 128]
    spec = load_model(_common.model_path("bus_grid.toml")).spec
    laws = {"mu1": geometric(0.8), "mu2": geometric(0.3)}
    rows = []
    print(f"{'n':>4} {'states':>9} {'transitions':>12} {'write cpu s':>11} {'wall s':>7} "
          f"{'M trans/s':>9} {'Storm read cpu s':>16} {'write/read':>10}")
    for n in sizes:
        world = GridWorld.make(n, n, start=(0, 0), slip=0.1,
                               regions={"A": [(n // 4, n // 2)], "B": [(3 * n // 4, 0)]})
        model = Model.from_game(world, spec, distributions=laws, name=f"bus{n}")
        mdp = build_product(model.game, model.spec, model.distributions, epsilon=0.01).mdp
        path = out / f"bench_drn_{n}.drn"
        _, wall, cpu = _timed(write_drn, mdp, mdp.target, path, overwrite=True)
        _, _, storm_cpu = _timed(stormpy.build_model_from_drn, str(path))
        path.unlink()
        rate = mdp.n_transitions / cpu / 1e6
        rows.append([n, mdp.n_states, mdp.n_transitions, cpu, wall, rate, storm_cpu,
                     cpu / storm_cpu])
        print(f"{n:4d} {mdp.n_states:9,d} {mdp.n_transitions:12,d} {cpu:11.2f} {wall:7.2f} "
              f"{rate:9.2f} {storm_cpu:16.2f} {cpu / storm_cpu:10.2f}")
    _common.write_csv(out / "bench_drn.csv",
                      ["n", "states", "transitions", "write_cpu_s", "write_wall_s",
                       "million_transitions_per_cpu_s", "storm_read_cpu_s",
                       "write_over_storm_read"], rows)
    return rows


if __name__ == "__main__":
    sys.exit(0 if main() else 1)

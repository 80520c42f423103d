"""The pictures of docs/sweeps.md, drawn by the library (what ``mitld-lp plot`` draws).

* ``bus_policy.png``: the paper's bus grid (models/bus_grid.toml), its optimal policy
  while both buses are pending and right after each bus arrives;
* ``bus_sweep.png``: models/sweeps/bus_sweep.toml's lower bound against the deadline T,
  one line per arrival rate of bus 2.

Run: ``python experiments/docs_figures.py [--quick] [--out DIR]``.  Without ``--out`` it
writes into ``docs/img`` (the committed pictures), with ``--quick`` into the scratch
folder; the test suite runs it and checks the pictures' sizes.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import _common as C

import mitld_lp
from mitld_lp.plot import Situation, policy_figure, save, sweep_figure
from mitld_lp.sweep import run_sweep

DOCS_IMG = C.ROOT / "docs" / "img"
POLICY_SIZE = (1200, 430)
SWEEP_SIZE = (720, 480)


def main(argv: list[str] | None = None) -> dict[str, Path]:
    ap = C.parser(__doc__.splitlines()[0])
    args = ap.parse_args(argv)
    if args.out is None and not args.quick:
        args.out = DOCS_IMG
    out = C.out_dir(args)
    start = time.perf_counter()
    result = mitld_lp.synthesize(mitld_lp.load_model(C.model_path("bus_grid.toml")))
    situations = [Situation(), Situation(occurred=frozenset({"b1"})),
                  Situation(occurred=frozenset({"b2"}))]
    written = {"policy": save(policy_figure(result, situations, size=POLICY_SIZE),
                              out / "bus_policy.png", overwrite=True)}
    with tempfile.TemporaryDirectory() as scratch:
        results = Path(scratch) / "bus_sweep.csv"
        run = run_sweep(C.MODELS / "sweeps" / "bus_sweep.toml", results)
        written["sweep"] = save(sweep_figure(results, "T", "lower", size=SWEEP_SIZE),
                                out / "bus_sweep.png", overwrite=True)
    print(f"bus grid: optimum in [{result.lower:.7f}, {result.upper:.7f}]")
    print(f"bus sweep: {len(run.rows)} points, {len(run.failed)} without a certified answer")
    for path in written.values():
        print(f"wrote {C.shown(path)}")
    print(f"({time.perf_counter() - start:.1f} s)")
    return written


if __name__ == "__main__":
    main()

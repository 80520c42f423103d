"""Calibration of the sweeps' gate (:mod:`mitld_lp.solvers.sweep_gate`): each block of
the interval iteration, swept by NumPy and swept compiled, in CPU seconds.

Per instance (QVBS posed as ``bench_qvbs.py`` poses it, or a ``bench_sweeps.py``
instance with ``--bus``), one child process per route: ``synthesize`` with every block
below the compiled size forced to one route (``numpy``: Jacobi sweeps and the policy
jump; ``compiled``: Gauss--Seidel, numba loaded before the solve and its load timed
apart), and per block (in the order the iteration meets them): its states, entries,
depth (:func:`mitld_lp.solvers.jump_cost.block_depth`), what the gate forecasts for each
route (entries touched) and picks, and what each route took: sweeps, CPU of the
sweeps, of the policy jumps (early and late), and of the set-up (the block built, its
order, renumbering and preparation).  A third child runs the default route (the gate)
for the answer and the solve.

::

    python experiments/gate_blocks.py --qvbs /work/shared/qvbs --only consensus.4-4.c2 \
        --bus bus_scaled_n64_d3 --out /tmp/gate

Written: ``gate_blocks.md``.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import _common  # noqa: E402
import bench_sweeps as bs  # noqa: E402
import profile_solve as ps  # noqa: E402

COLUMNS = ("instance", "route", "block", "states", "entries", "depth", "numpy_forecast",
           "compiled_forecast", "gate", "sweeps", "sweep_cpu", "jump_cpu", "setup_cpu")


def child(job: dict[str, Any]) -> dict[str, Any]:
    """One route's solve with its blocks timed (module docs)."""
    from mitld_lp import load_model, synthesize
    from mitld_lp.solvers import iteration as it
    from mitld_lp.solvers import kernels, sweep_gate

    if "bus" in job:
        from bench_scaling import Instance

        model = bs._model(Instance(*job["bus"]))
    else:
        model = load_model(job["model"], max_states=job["max_states"])
    bs.preload()
    route = job["route"]
    load = 0.0
    if route == "compiled":
        c = time.process_time()
        kernels.compiled_kernel()
        load = time.process_time() - c
    blocks: list[dict[str, Any]] = []
    gate = sweep_gate.use_compiled

    def use(entries: int, block_entries: int, block: Any = None, *rest: Any) -> bool:
        f = sweep_gate.forecast(block, loaded=False)
        blocks.append(dict(states=int(block.states.size), entries=int(block_entries),
                           depth=f.depth, numpy_forecast=f.numpy,
                           compiled_forecast=f.compiled,
                           gate=bool(gate(entries, block_entries, block, *rest)),
                           sweeps=0, sweep_cpu=0.0, jump_cpu=0.0, setup_cpu=0.0))
        if route == "default" or block_entries >= kernels.COMPILED_MIN_BLOCK_ENTRIES:
            return blocks[-1]["gate"]
        return route == "compiled"

    inside: set[str] = set()  # the keys being timed (a jump inside the early jump once)

    def timed(func: Any, key: str) -> Any:
        def wrapped(*args: Any, **kwargs: Any) -> Any:
            if key in inside:
                return func(*args, **kwargs)
            inside.add(key)
            c = time.process_time()
            before = args[7].iterations if key == "sweep_cpu" else 0
            try:
                return func(*args, **kwargs)
            finally:
                inside.discard(key)
                if blocks:
                    blocks[-1][key] += time.process_time() - c
                    if key == "sweep_cpu":
                        blocks[-1]["sweeps"] += args[7].iterations - before
        return wrapped

    it.use_compiled = use
    it._block_sweeps = timed(it._block_sweeps, "sweep_cpu")
    it.jump = timed(it.jump, "jump_cpu")
    it._early_jump = timed(it._early_jump, "jump_cpu")
    it.value_order = timed(it.value_order, "setup_cpu")
    it.Prepared = timed(it.Prepared, "setup_cpu")
    r = synthesize(model)
    return dict(blocks=blocks, value=r.lower, upper=r.upper, solve_cpu=r.solve_cpu,
                numba_load=load)


def main(argv: list[str] | None = None) -> int:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, default=None)
    ap.add_argument("--only", nargs="*", default=(), metavar="NAME")
    ap.add_argument("--bus", nargs="*", default=(), metavar="NAME")
    ap.add_argument("--routes", nargs="*", default=("numpy", "compiled", "default"))
    ap.add_argument("--child", nargs=2, default=None, help=ps.argparse_hidden())
    args = ap.parse_args(argv)
    if args.child:  # run by profile_solve._run_child
        work = Path(args.child[1])
        job = json.loads((work / "job.json").read_text(encoding="utf-8"))
        (work / f"{args.child[0]}.json").write_text(json.dumps(child(job)), encoding="utf-8")
        return 0
    out = _common.out_dir(args)
    rows, lines = [], []
    with tempfile.TemporaryDirectory(prefix="gate_blocks_") as tmp:
        work = Path(tmp)
        chosen = ps.bus_jobs(args.bus)
        if args.only:
            if args.qvbs is None:
                ap.error("--only needs --qvbs")
            chosen = ps.chosen_jobs(args.qvbs, False, set(args.only), work, 0) + chosen
        for inst, job in chosen:
            for route in args.routes:
                got = ps._run_child("blocks", dict(job, route=route), work, __file__)
                if "error" in got:
                    lines.append(f"{inst.name} {route}: error {got['error']}")
                    continue
                lines.append(f"{inst.name} {route}: value [{got['value']!r}, "
                             f"{got['upper']!r}], solve {got['solve_cpu']:.3f} s CPU, "
                             f"numba loaded before it in {got['numba_load']:.3f} s")
                for i, b in enumerate(got["blocks"]):
                    rows.append([inst.name, route, i, *(b[k] for k in COLUMNS[3:])])
                print(lines[-1], flush=True)
    shown = [[f"{v:.3g}" if isinstance(v, float) else v for v in r] for r in rows]
    text = ("## The blocks of the interval iteration by route (CPU seconds; forecasts in "
            "entries touched)\n\n" + _common.markdown_table(COLUMNS, shown) + "\n\n"
            + "\n".join(f"- {x}" for x in lines) + "\n")
    _common.write_text(out / "gate_blocks.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

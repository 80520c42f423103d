"""Benchmark: the sweeps' gate on the sensed cases, block by block (which route it picks,
what each route costs there).

The sensed route iterates both truncation models at once: four columns a block, the
compiled kernel's two-model sweeps (:mod:`mitld_lp.solvers.sweep_four`) where the gate
(:mod:`mitld_lp.solvers.sweep_gate`) sends a block to the compiled kernel, NumPy's
Jacobi sweeps otherwise.  Per case (``bench_sensed``'s, posed as ``synthesize`` poses it),
one child process per route, as :mod:`gate_blocks` runs them (its child, the case's model
handed in where it loads a model file): ``numpy`` (every block below the compiled size
swept by NumPy), ``compiled`` (every block compiled, numba's kernel loaded before the
solve and its load timed apart: ``load``), ``cold`` (every block compiled, the kernel
loaded where the first block is swept, as a compiled pick of the gate loads it: its load
counted in the route's sum, its first call in that block's figure) and ``default`` (the
gate's picks).  Per block, in the order the iteration meets them: its states, entries,
depth, the one-model rule's forecasts (``gate_blocks``': entries touched, numba not
loaded; a two-model block is decided by ``sweep_gate.prefers_four``'s) and the gate's
pick, then each route's sweeps and CPU seconds (sweeps plus set-up: the value order, the
preparation).  ``best``
names the cheaper route over the case's blocks as the solve meets them (``numpy`` or
``cold``: the sensed iteration starts with the kernel not loaded, ``loaded_at_start``).

Run: ``python experiments/bench_sensed_gate.py [--quick] [--out DIR] [--only TEXT]``
(default: issue 45's case, ``bench_sensed.FULL[0]``; ``--only``: the full cases whose
name holds ``TEXT``; ``--quick``: ``bench_sensed.QUICK``'s).  Writes
``bench_sensed_gate.md``.
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
import bench_sensed as B  # noqa: E402
import profile_solve as ps  # noqa: E402

TITLE = "## The sensed cases' blocks by route (CPU seconds; forecasts in entries touched)\n\n"
ROUTES = ("numpy", "compiled", "cold", "default")
HEADER = ("case", "block", "states", "entries", "depth", "numpy_forecast",
          "compiled_forecast", "gate", "numpy_sweeps", "numpy_cpu", "compiled_sweeps",
          "compiled_cpu", "cold_cpu", "default_cpu")


def child(job: dict[str, Any]) -> dict[str, Any]:
    """One route's solve of one sensed case, its blocks timed (:func:`gate_blocks.child`)."""
    import gate_blocks

    import mitld_lp
    from mitld_lp.solvers import iteration, kernels, sweep_gate

    model = B.case_model(job["index"], job["quick"])
    mitld_lp.load_model = lambda *_a, **_k: model  # gate_blocks' child loads a model file
    at_start: list[bool] = []
    inner = iteration.interval_iterations

    def iterations(*args: Any, **kwargs: Any) -> Any:
        at_start.append(kernels.kernel_loaded())
        return inner(*args, **kwargs)

    iteration.interval_iterations = iterations
    route = job["route"]
    load = [0.0]  # the cold route's kernel load (inside the gate's call)
    if route == "cold":  # the gate's pick made compiled: the kernel loaded at the first

        def cold(*_a: Any, **_k: Any) -> bool:
            c = time.process_time()
            try:
                return kernels.compiled_kernel() is not None
            finally:
                load[0] += time.process_time() - c

        sweep_gate.use_compiled = cold
        route = "default"
    got = gate_blocks.child(dict(model="", max_states=None, route=route))
    got["loaded_at_start"] = bool(at_start and at_start[0])
    if job["route"] == "cold":
        got["numba_load"] = load[0]
    return got


def _answer(kind: str, work: str) -> int:
    """The child's side of ``profile_solve._run_child``: its job read, its answer written."""
    job = json.loads(Path(work, "job.json").read_text(encoding="utf-8"))
    Path(work, kind + ".json").write_text(json.dumps(child(job)), encoding="utf-8")
    return 0


def _cpu(b: dict[str, Any]) -> float:
    return float(b["sweep_cpu"] + b["setup_cpu"] + b["jump_cpu"])


def main(argv: list[str] | None = None) -> int:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--only", default=None, metavar="TEXT")
    ap.add_argument("--child", nargs=2, default=None, help=ps.argparse_hidden())
    args = ap.parse_args(argv)
    if args.child:  # run by profile_solve._run_child
        return _answer(*args.child)
    out = _common.out_dir(args)
    cases = B.QUICK if args.quick else B.FULL
    chosen = [i for i, c in enumerate(cases)
              if (B.name_of(c) == B.name_of(B.FULL[0]) if args.only is None and not args.quick
                  else args.only is None or args.only in B.name_of(c))]
    rows, lines = [], []
    with tempfile.TemporaryDirectory(prefix="bench_sensed_gate_") as tmp:
        for i in chosen:
            name = B.name_of(cases[i])
            got = {r: ps._run_child("blocks", dict(index=i, quick=args.quick, route=r),
                                    Path(tmp), __file__) for r in ROUTES}
            if any("error" in g for g in got.values()):
                lines.append(f"{name}: error {[g.get('error') for g in got.values()]}")
                print(lines[-1], flush=True)
                continue
            blocks = [got[r]["blocks"] for r in ROUTES]
            for k, (n, c, cold, d) in enumerate(zip(*blocks, strict=True)):
                rows.append([name, k, n["states"], n["entries"], n["depth"],
                             f"{n['numpy_forecast']:.3g}", f"{n['compiled_forecast']:.3g}",
                             "compiled" if d["gate"] else "numpy", n["sweeps"],
                             f"{_cpu(n):.4f}", c["sweeps"], f"{_cpu(c):.4f}",
                             f"{_cpu(cold):.4f}", f"{_cpu(d):.4f}"])
            numpy = sum(_cpu(b) for b in blocks[0])
            compiled = sum(_cpu(b) for b in blocks[1]) + got["compiled"]["numba_load"]
            cold = sum(_cpu(b) for b in blocks[2]) + got["cold"]["numba_load"]
            best = "cold" if cold < numpy else "numpy"
            d = got["default"]
            lines.append(
                f"{name}: [{d['value']!r}, {d['upper']!r}] on every route "
                f"({all(g['value'] == d['value'] and g['upper'] == d['upper'] for g in got.values())}); "  # noqa: E501
                f"{len(blocks[0])} block(s); NumPy {numpy:.4f} s, compiled {compiled:.4f} s "
                f"(its load before the solve {got['compiled']['numba_load']:.4f}), cold "
                f"{cold:.4f} s (its load at the first block "
                f"{got['cold']['numba_load']:.4f}); best {best}; the gate picks "
                f"{['compiled' if b['gate'] else 'numpy' for b in blocks[3]]}; "
                f"kernel loaded at the iteration's start: {d['loaded_at_start']}")
            print(lines[-1], flush=True)
    body = _common.markdown_table(HEADER, rows) + "\n" + "".join(f"- {x}\n" for x in lines)
    _common.write_text(out / "bench_sensed_gate.md", TITLE + body)
    print(TITLE + body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""What is alive at the traced peak of one solve stage, and where the stage stood then.

One QVBS instance, this checkout's package (run from the checkout's root).  The
synthesis runs once untraced (kernels compiled and loaded, the bracket noted), then
again with ``tracemalloc`` (``--frames`` frames) on from the synthesis's entry and a
profile hook on the package's functions only while the stage ``--stage`` runs: at each
call or return of one where the traced size has passed the last snapshot's by
``--step`` (fraction), a snapshot is taken, so the last one is within that step of the
stage's traced peak.  Printed: the traced peak of the stage and of the synthesis in
bytes per product transition above the traced size before the synthesis, and the
allocation sites alive at the last snapshot grouped by their innermost package frames::

    python experiments/peak_sites.py <QVBS benchmarks dir> <instance> \\
        --stage mitld_lp.solvers.iteration:interval_iterations
"""

from __future__ import annotations

import argparse
import collections
import importlib
import sys
import tempfile
import tracemalloc
from pathlib import Path
from typing import Any


def _model(benchmarks: Path, name: str) -> Any:
    sys.path[:0] = [str(Path(__file__).resolve().parent)]
    import bench_qvbs as bq

    from mitld_lp import load_model

    work = Path(tempfile.mkdtemp(prefix="peak_sites_"))
    found, _ = bq.jobs(benchmarks, 0, bq.MAX_STATES, bq.FAMILIES, work)
    job = next(j for i, j in found if i.name == name)
    model = load_model(job["model"], max_states=job["max_states"])
    bq.bs.preload()
    return model


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("benchmarks", type=Path)
    ap.add_argument("instance")
    ap.add_argument("--stage", default="mitld_lp.solvers.lp:solve_lp")
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--step", type=float, default=0.02)
    ap.add_argument("--top", type=int, default=30)
    ap.add_argument("--depth", type=int, default=3, help="package frames a group shows")
    args = ap.parse_args(argv)
    model = _model(args.benchmarks, args.instance)
    from mitld_lp import synthesize

    r = synthesize(model)
    n, first = r.mdp.n_transitions, (repr(r.lower), repr(r.upper))
    del r
    module, attr = args.stage.split(":")
    mod = importlib.import_module(module)
    stage = getattr(mod, attr)
    state: dict[str, Any] = {"last": 0, "snap": None, "where": "", "peak": 0}

    def hook(frame: Any, event: str, arg: Any) -> None:
        if event not in ("call", "return"):
            return
        if "mitld_lp" not in frame.f_code.co_filename:
            return
        cur = tracemalloc.get_traced_memory()[0]
        if cur > state["last"] * (1.0 + args.step):
            state["last"] = cur
            state["snap"] = tracemalloc.take_snapshot()
            state["where"] = (f"{event} {frame.f_code.co_filename.split('mitld_lp/')[-1]}:"
                              f"{frame.f_lineno} ({frame.f_code.co_name})")

    def traced(*a: Any, **k: Any) -> Any:
        entry = tracemalloc.get_traced_memory()[0]
        state["last"] = entry
        tracemalloc.reset_peak()
        sys.setprofile(hook)
        try:
            return stage(*a, **k)
        finally:
            sys.setprofile(None)
            state["peak"] = tracemalloc.get_traced_memory()[1]
            state["entry"] = entry

    setattr(mod, attr, traced)
    tracemalloc.start(args.frames)
    base = tracemalloc.get_traced_memory()[0]
    r = synthesize(model)
    whole = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert (repr(r.lower), repr(r.upper)) == first, "two runs, two brackets"
    print(f"{args.instance}: {n} transitions, bracket {first}")
    print(f"synthesis traced peak {(whole - base) / n:.1f} B/t; stage {args.stage}: "
          f"entry {(state['entry'] - base) / n:.1f}, peak {(state['peak'] - base) / n:.1f}"
          f", last snapshot {(state['last'] - base) / n:.1f} at {state['where']}")
    snap = state["snap"]
    if snap is None:
        return
    groups: collections.Counter[str] = collections.Counter()
    for trace in snap.traces:
        frames = [f"{f.filename.split('mitld_lp/')[-1]}:{f.lineno}"
                  for f in trace.traceback if "mitld_lp/" in f.filename]
        groups[" < ".join(frames[::-1][:args.depth]) if frames else "other"] += trace.size
    for key, size in groups.most_common(args.top):
        print(f"{size / n:7.2f}  {key}")


if __name__ == "__main__":
    main(sys.argv[1:])

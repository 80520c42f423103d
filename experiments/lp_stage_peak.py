"""The LP stage's traced peak on one QVBS instance, fast: ``tracemalloc`` (one frame) on
from the entry of ``solve_lp`` only, so the product, the analysis and the iteration run
untraced.  Printed in bytes per transition above the traced size at the LP's entry, with
each ``certified_greedy`` call's own peak above its entry, and the answer beside them::

    python experiments/lp_stage_peak.py <checkout> <QVBS benchmarks dir> <instance>

Run once per checkout (before/after, the checkout's package on ``PYTHONPATH``).
``memory_stages.py`` (``bench_qvbs.py --memory``) traces the whole synthesis with
tracebacks, which took over 15 CPU minutes on zeroconf 1000-4 on a loaded machine.
The CPU times printed are under tracing."""

from __future__ import annotations

import sys
import tempfile
import time
import tracemalloc
from pathlib import Path
from typing import Any


def main(argv: list[str]) -> None:
    root, benchmarks, name = Path(argv[0]).resolve(), Path(argv[1]), argv[2]
    sys.path[:0] = [str(root), str(root / "experiments")]
    import bench_qvbs as bq

    import mitld_lp.solvers.lp as lpm
    import mitld_lp.solvers.lp_blocks as lb
    from mitld_lp import load_model, synthesize

    work = Path(tempfile.mkdtemp(prefix="lp_stage_peak_"))
    found, _ = bq.jobs(benchmarks, 0, bq.MAX_STATES, bq.FAMILIES, work)
    job = next(j for i, j in found if i.name == name)
    model = load_model(job["model"], max_states=job["max_states"])
    bq.bs.preload()
    out: dict[str, Any] = {"greedy": []}
    solve_lp, greedy = lpm.solve_lp, lb.certified_greedy

    def traced_lp(*a: Any, **k: Any) -> Any:
        tracemalloc.start(1)
        base, t = tracemalloc.get_traced_memory()[0], time.process_time()
        try:
            return solve_lp(*a, **k)
        finally:
            out["lp_cpu"] = time.process_time() - t
            out["lp_peak"] = tracemalloc.get_traced_memory()[1] - base
            tracemalloc.stop()

    def traced_greedy(*a: Any, **k: Any) -> Any:
        cur, t = tracemalloc.get_traced_memory()[0], time.process_time()
        tracemalloc.reset_peak()
        got = greedy(*a, **k)
        out["greedy"].append((tracemalloc.get_traced_memory()[1] - cur,
                              time.process_time() - t))
        return got

    lpm.solve_lp, lb.certified_greedy = traced_lp, traced_greedy
    r = synthesize(model)
    n = r.mdp.n_transitions
    print(f"{root} {name}: transitions {n}, lower {r.lower!r}, upper {r.upper!r}")
    print(f"LP stage traced peak above its entry: {out['lp_peak'] / n:.1f} B/t, "
          f"cpu {out['lp_cpu']:.3f} (traced)")
    for peak, cpu in out["greedy"]:
        print(f"  certified_greedy: traced peak above its entry {peak / n:.1f} B/t, "
              f"cpu {cpu:.3f}")


if __name__ == "__main__":
    main(sys.argv[1:])

"""The LP stage's CPU and traced peak on QVBS instances, fast: ``tracemalloc`` (one
frame) on from the entry of ``solve_lp`` only, so the product, the analysis and the
iteration run untraced.  Printed in bytes per transition above the traced size at the
LP's entry, with each ``certified_greedy`` call's own peak above its entry, and the
answer beside them::

    python experiments/lp_stage_peak.py <checkout> <QVBS benchmarks dir> <instance>...
    python experiments/lp_stage_peak.py <checkout> <QVBS dir> <instance>... \\
        --compare <other checkout> [--out FILE.md]

Each instance and checkout runs in a child process of its own (the checkout's package
on ``sys.path``), two synthesis runs a child: the first untraced, for the LP stage's
CPU seconds (``solve_lp``, process time) and the solve's (``synthesize`` after the
product: the stages ``bench_qvbs.py`` counts as the solve, here the LP, the iteration,
the analysis and the certificate, each timed in place), the second traced, for the
peak.  With ``--compare`` the other checkout runs right after, instance by instance,
so the machine's load hits both; the brackets are compared to the bit.
``memory_stages.py`` (``bench_qvbs.py --memory``) traces the whole synthesis with
tracebacks, which took over 15 CPU minutes on zeroconf 1000-4 on a loaded machine.

``--alive`` (one checkout, one instance) instead lists what is alive at the greedy
check's first batch: the whole second synthesis traced (25 frames), one snapshot there,
each allocation grouped by its frames from the LP stage's first (``LP``) or, made
before the stage, by its last three frames in the package (``caller``), in bytes per
transition above the traced size before ``synthesize`` (about a minute on zeroconf
1000-4)::

    python experiments/lp_stage_peak.py <checkout> <QVBS dir> <instance> --alive
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path
from typing import Any

#: the solve's stages, timed in place in the child (module, attribute)
SOLVE_STAGES = (("mitld_lp.solvers.analysis", "analyse"),
                ("mitld_lp.solvers.iteration", "interval_iterations"),
                ("mitld_lp.solvers.lp", "solve_lp"),
                ("mitld_lp.solvers.certify", "certify"))


def _model(root: Path, benchmarks: Path, name: str) -> Any:
    """The QVBS instance ``name`` loaded with ``root``'s package (put first on the path),
    the bench's imports preloaded."""
    sys.path[:0] = [str(root), str(root / "experiments")]
    import bench_qvbs as bq

    from mitld_lp import load_model

    work = Path(tempfile.mkdtemp(prefix="lp_stage_peak_"))
    found, _ = bq.jobs(benchmarks, 0, bq.MAX_STATES, bq.FAMILIES, work)
    job = next(j for i, j in found if i.name == name)
    model = load_model(job["model"], max_states=job["max_states"])
    bq.bs.preload()
    return model


def child(root: Path, benchmarks: Path, name: str) -> dict[str, Any]:
    """One instance in this process with ``root``'s package: the LP stage's and the
    solve's CPU (untraced), then the LP stage's traced peak."""
    model = _model(root, benchmarks, name)
    import importlib

    import mitld_lp.solvers.lp as lpm
    import mitld_lp.solvers.lp_blocks as lb
    from mitld_lp import synthesize

    out: dict[str, Any] = {"greedy": [], "stage_cpu": {}, "traced": False}
    greedy = lb.certified_greedy

    def timed(key: str, f: Any) -> Any:
        def run(*a: Any, **k: Any) -> Any:
            t = time.process_time()
            try:
                return f(*a, **k)
            finally:
                if not out["traced"]:
                    out["stage_cpu"][key] = (out["stage_cpu"].get(key, 0.0)
                                             + time.process_time() - t)
        return run

    originals = []
    for module, attr in SOLVE_STAGES:
        mod = importlib.import_module(module)
        originals.append((mod, attr, getattr(mod, attr)))
        setattr(mod, attr, timed(attr, getattr(mod, attr)))
    lp_timed = lpm.solve_lp
    r = synthesize(model)
    first = (repr(r.lower), repr(r.upper))

    def traced_lp(*a: Any, **k: Any) -> Any:
        tracemalloc.start(1)
        base = tracemalloc.get_traced_memory()[0]
        try:
            return lp_timed(*a, **k)
        finally:
            out["lp_peak"] = tracemalloc.get_traced_memory()[1] - base
            tracemalloc.stop()

    def traced_greedy(*a: Any, **k: Any) -> Any:
        cur = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        got = greedy(*a, **k)
        out["greedy"].append((tracemalloc.get_traced_memory()[1] - cur) / n)
        return got

    out["traced"] = True
    n = r.mdp.n_transitions
    del r
    lpm.solve_lp, lb.certified_greedy = traced_lp, traced_greedy
    r = synthesize(model)
    assert (repr(r.lower), repr(r.upper)) == first, "two runs, two brackets"
    return {"instance": name, "transitions": n, "lower": first[0], "upper": first[1],
            "lp_cpu": out["stage_cpu"]["solve_lp"],
            "solve_cpu": sum(out["stage_cpu"].values()),
            "stage_cpu": out["stage_cpu"], "lp_peak": out["lp_peak"] / n,
            "greedy_peaks": out["greedy"]}


def alive(root: Path, benchmarks: Path, name: str, top: int = 40) -> list[str]:
    """What is alive at the first batch of the first greedy check (``--alive``)."""
    import collections

    model = _model(root, benchmarks, name)
    import mitld_lp.solvers.greedy_block as gb
    from mitld_lp import synthesize

    r = synthesize(model)  # untraced: the kernels compiled and loaded
    n, first = r.mdp.n_transitions, (repr(r.lower), repr(r.upper))
    del r
    snaps: list[Any] = []
    owners = gb._owners

    def snapped(*a: Any) -> Any:
        got = owners(*a)
        if not snaps:
            snaps.append((tracemalloc.get_traced_memory()[0], tracemalloc.take_snapshot()))
        return got

    gb._owners = snapped
    tracemalloc.start(25)
    base = tracemalloc.get_traced_memory()[0]
    r = synthesize(model)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert (repr(r.lower), repr(r.upper)) == first, "two runs, two brackets"
    lines = [f"{name}: {n} transitions, bracket {first}; traced peak of the synthesis "
             f"{(peak - base) / n:.2f} B/t"]
    if not snaps:
        return lines + ["no greedy check ran"]
    at, snap = snaps[0]
    lp = ("solvers/lp.py", "solvers/lp_blocks.py", "solvers/greedy_block.py")
    groups: collections.Counter[str] = collections.Counter()
    for trace in snap.traces:
        frames = [f"{f.filename.split('mitld_lp/')[-1]}:{f.lineno}"
                  for f in trace.traceback if "mitld_lp" in f.filename]
        ours = [i for i, f in enumerate(frames) if f.startswith(lp)]
        groups[("LP " + " > ".join(frames[ours[0]:])) if ours else
               ("caller " + " > ".join(frames[-3:])) if frames else "other"] += trace.size
    lines.append(f"alive at the greedy check's first batch: {(at - base) / n:.2f} B/t "
                 f"(LP {sum(v for k, v in groups.items() if k.startswith('LP')) / n:.2f}, "
                 f"caller {sum(v for k, v in groups.items() if k.startswith('caller')) / n:.2f})")
    lines += [f"{v / n:7.2f}  {k}" for k, v in groups.most_common(top)]
    return lines


def run_child(root: Path, benchmarks: Path, name: str, script: str = __file__
              ) -> dict[str, Any]:
    """``script --child root benchmarks name`` in a process of its own with ``root``'s
    package: the JSON it prints last, or the error."""
    env = dict(os.environ, PYTHONPATH=str(root))
    got = subprocess.run([sys.executable, script, "--child", str(root), str(benchmarks),
                          name], capture_output=True, text=True, env=env, check=False)
    if got.returncode:
        return {"instance": name, "error": got.stderr[-2000:]}
    return json.loads(got.stdout.strip().splitlines()[-1])


def arguments(argv: list[str], doc: str) -> tuple[argparse.Namespace, list[Path]]:
    """The command line this script and ``lp_stage_parts.py`` share, and the
    checkouts to run (this one, then ``--compare``'s)."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("checkout", type=Path)
    ap.add_argument("benchmarks", type=Path)
    ap.add_argument("instances", nargs="+")
    ap.add_argument("--compare", type=Path, help="another checkout, run right after")
    ap.add_argument("--out", type=Path, help="also write the table here (markdown)")
    args = ap.parse_args(argv)
    return args, [args.checkout.resolve()] + ([args.compare.resolve()] if args.compare
                                              else [])


def main(argv: list[str]) -> None:
    if argv and argv[0] == "--child":
        print(json.dumps(child(Path(argv[1]).resolve(), Path(argv[2]), argv[3])))
        return
    if "--alive" in argv:
        rest = [a for a in argv if a != "--alive"]
        print("\n".join(alive(Path(rest[0]).resolve(), Path(rest[1]), rest[2])))
        return
    args, roots = arguments(argv, __doc__)
    lines = ["| instance | transitions | lower | same bracket | LP CPU | solve CPU | "
             "LP traced peak B/t | greedy peaks B/t | checkout |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name in args.instances:
        rows = [run_child(root, args.benchmarks, name) for root in roots]
        same = (len(rows) == 2 and "error" not in rows[0] and "error" not in rows[1]
                and (rows[0]["lower"], rows[0]["upper"]) == (rows[1]["lower"],
                                                             rows[1]["upper"]))
        for root, row in zip(roots, rows, strict=True):
            if "error" in row:
                lines.append(f"| {name} | | | | | | | | {root} (error) |")
                print(row["error"], file=sys.stderr)
                continue
            peaks = ", ".join(f"{p:.1f}" for p in row["greedy_peaks"]) or "-"
            lines.append(
                f"| {name} | {row['transitions']} | {row['lower']} | "
                f"{'yes' if same else ('-' if len(rows) == 1 else 'NO')} | "
                f"{row['lp_cpu']:.3f} | {row['solve_cpu']:.3f} | {row['lp_peak']:.1f} | "
                f"{peaks} | {root} |")
        print("\n".join(lines[-len(rows):]), flush=True)
    finish(lines, args.out)


def finish(lines: list[str], out: Path | None) -> None:
    """The table printed whole, and written to ``out`` if given."""
    text = "\n".join(lines)
    print(text)
    if out:
        out.write_text(text + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])

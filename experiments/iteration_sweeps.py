"""The interval iteration split: per block, what runs and what it costs (CPU seconds).

Per instance, in a child process of its own (the model posed as ``bench_qvbs.py`` or
``bench_sweeps.py`` poses it, the solver modules preloaded as there): ``synthesize``
runs once with :func:`mitld_lp.solvers.iteration.interval_iterations` captured, then
the captured call runs again

* ``--repeats`` times plain (no wrapper): ``iteration_s``, the least CPU of those, with
  its sweeps and the initial state's bracket (both ends printed to the bit, ``repr``);
* once with the iteration's parts wrapped (each part's CPU inside it): the setup of the
  whole pass (``blocks``: the quotient's components and levels; ``levels``: the single
  states' runs, shared with the LP stage; ``reach``: the states the initial one
  reaches, and the state graph it is searched on), the single states' walk
  (``singles``), each model's result (``result``: the bounds lifted to the product),
  and per block with states of its own
  (a non-trivial level): its states and entries, the route (``compiled`` Gauss--Seidel
  or ``numpy`` Jacobi) and which rule of :mod:`mitld_lp.solvers.sweep_gate` decided
  (``product small``: a product under ``COMPILED_MIN_ENTRIES``; ``size``: a block of at
  least ``COMPILED_MIN_BLOCK_ENTRIES``; ``forecast``: the block's depth forecast, with
  the depth and both forecasts in compiled sweeps' entries; ``bound``: decided for
  NumPy without the depth search; ``no numba``), its setup (``block``: ``Block.of``;
  ``order``: the value order and the renumbering; ``prepare``: the self-loops and the
  index arrays), its sweeps (count, CPU, per sweep), the stop test (``excess`` read by
  the NumPy sweeps and between chunks; the compiled kernel reads its own inside the
  sweep) and the policy jump (``jump``, ``early jump``), and the rest of the pass
  (``other``: exits, copies, the result's lift).

The wrapped run's total is printed beside the plain one (the wrappers cost a little).

::

    python experiments/iteration_sweeps.py --qvbs /work/shared/qvbs \\
        --only consensus.4-4.c2 zeroconf.1000-4-false.correct_max \\
        --bus bus_scaled_n64_d3 bus_scaled_n128_d3 --compare /tmp/base
    python experiments/iteration_sweeps.py --qvbs /work/shared/qvbs --quick

``--rounds`` also runs the captured iteration once with the policy jump's rounds of
policy iteration watched one by one (:func:`_watch_rounds`).
``--routes`` also runs the captured iteration with every block compiled and with none
(numba loaded in the first), each with its sweeps and bracket: what the gate chose
between.  ``--compare DIR`` runs every child again with the ``mitld_lp`` of another checkout (the
same harness) right after this one's, and prints both with ``same_bracket`` (both ends
of the initial state's bracket equal to the bit).  ``--quick`` runs one small QVBS
instance into ``experiments/out/quick`` (or ``--out``).  Written: ``iteration_sweeps.json``
and ``iteration_sweeps.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import _common  # noqa: E402

QUICK = ("consensus.2-2.c2",)
BUDGET = 900.0
PASS_PARTS = ("blocks", "levels", "reach", "singles", "result")
BLOCK_PARTS = ("gate", "block", "order", "prepare", "sweeps_cpu", "stop_test", "jump",
               "early_jump")


# ----------------------------------------------------------------------------- the child


def _model(job: dict[str, Any]) -> Any:
    import bench_sweeps as bs

    if "bus" in job:
        from bench_scaling import Instance

        model = bs._model(Instance(*job["bus"]))
    else:
        from mitld_lp import load_model

        model = load_model(job["model"], max_states=job["max_states"])
    bs.preload()
    return model


def _cpu() -> float:
    return time.process_time()


class _Split:
    """The wrappers over the iteration's parts and what they read."""

    def __init__(self) -> None:
        self.parts = dict.fromkeys(PASS_PARTS, 0.0)
        self.blocks: list[dict[str, Any]] = []
        self.current: dict[str, Any] | None = None
        self.depth = 0  # nesting of wrapped calls: only the outermost counts
        self.held = 0.0  # Block.of's CPU before the gate names its block
        self.own = 0.0  # the split's own reads (the gate's rule read again)

    def add(self, part: str, seconds: float) -> None:
        if part in self.parts:
            self.parts[part] += seconds
        elif self.current is not None:
            self.current[part] = self.current.get(part, 0.0) + seconds

    def wrap(self, owner: Any, name: str, part: str, after: Any = None) -> None:
        func = getattr(owner, name, None)
        if func is None:
            return
        split = self

        def wrapped(*args: Any, **kwargs: Any) -> Any:
            if split.depth:
                out = func(*args, **kwargs)
                if after is not None:
                    after(split, args, out)
                return out
            split.depth += 1
            c = _cpu()
            try:
                out = func(*args, **kwargs)
            finally:
                split.depth -= 1
                split.add(part, _cpu() - c)
            if after is not None:
                after(split, args, out)
            return out

        setattr(owner, name, wrapped)


def _gate_reason(args: tuple, loaded: bool, fast: bool) -> dict[str, Any]:
    """Which rule of the sweep gate decided a block (``use_compiled(entries,
    block_entries, block)``; ``loaded``: the kernel loaded before it asked; ``fast``
    its answer), read again outside the timed part (numba never loaded here)."""
    from mitld_lp.solvers import kernels, sweep_gate

    entries, block_entries = args[0], args[1]
    block = args[2] if len(args) > 2 else None
    if entries < kernels.COMPILED_MIN_ENTRIES:
        return {"rule": "product small"}
    if block_entries >= kernels.COMPILED_MIN_BLOCK_ENTRIES:
        return {"rule": "size" if fast else "no numba"}
    states = int(block.states.size)
    entries_f = float(block.inner.nnz)
    sweep = entries_f + float(block.choices.shape[0])
    if (states <= sweep_gate.JACOBI_SWEEPS
            or sweep_gate._numpy(states, entries_f, sweep, states)
            <= sweep_gate._compiled(sweep, 0, loaded)):
        return {"rule": "bound"}
    f = sweep_gate.forecast(block, loaded)
    return {"rule": "forecast" if fast or not f.compiled < f.numpy
            or f.depth <= sweep_gate.JACOBI_SWEEPS else "no numba",
            "depth": f.depth, "numpy_work": f.numpy, "compiled_work": f.compiled}


def child_split(job: dict[str, Any]) -> dict[str, Any]:
    """The captured iteration: plain ``repeats`` times, then once split."""
    model = _model(job)
    from mitld_lp import synthesize
    from mitld_lp.solvers import iteration

    plain = iteration.interval_iterations
    captured: list[tuple[tuple, dict]] = []

    def capture(*args: Any, **kwargs: Any) -> Any:
        if not captured:
            captured.append((args, kwargs))
        return plain(*args, **kwargs)

    iteration.interval_iterations = capture
    r = synthesize(model)
    iteration.interval_iterations = plain
    out: dict[str, Any] = {"value": r.lower, "upper": r.upper, "solve_cpu": r.solve_cpu}
    if not captured:
        return dict(out, error="no interval iteration in this solve")
    args, kwargs = captured[0]
    q = args[1][0]
    out.update(quotient_states=int(q.n_states), quotient_entries=int(q.matrix.nnz),
               models=len(args[1]))
    best = None
    for _ in range(job["repeats"]):
        c = _cpu()
        results = plain(*args, **kwargs)
        spent = _cpu() - c
        best = spent if best is None else min(best, spent)
    res = results[0]
    out.update(iteration_s=best, sweeps=res.iterations,
               lower=repr(res.value_lower), upper_iter=repr(res.value_upper),
               brackets=[[repr(x.value_lower), repr(x.value_upper)] for x in results])
    if job.get("routes"):  # every block compiled, then none (the gate's alternatives)
        for name, compiled in (("all_compiled", True), ("all_numpy", False)):
            c = _cpu()
            got = plain(*args, **dict(kwargs, compiled=compiled))
            out[name] = {"iteration_s": _cpu() - c, "sweeps": got[0].iterations,
                         "bracket": [repr(got[0].value_lower), repr(got[0].value_upper)]}
    split = _instrument(iteration)
    c = _cpu()
    results = plain(*args, **kwargs)
    total = _cpu() - c
    counted = split.held + sum(split.parts.values()) + sum(
        v for b in split.blocks for k, v in b.items() if k in BLOCK_PARTS)
    out.update(split_total_s=total, parts=split.parts, blocks=split.blocks,
               other=total - counted - split.own, split_own=split.own,
               split_same=[[repr(x.value_lower), repr(x.value_upper)]
                           for x in results] == out["brackets"])
    if job.get("rounds"):
        rounds, calls = _watch_rounds()
        c = _cpu()
        results = plain(*args, **kwargs)
        out.update(rounds_total_s=_cpu() - c, rounds=rounds, round_calls=calls,
                   rounds_same=[[repr(x.value_lower), repr(x.value_upper)]
                                for x in results] == out["brackets"])
    return out


def _watch_rounds() -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The policy jump's rounds of policy iteration wrapped (``--rounds``): per round
    the block's states, the policy's chain (its entries, its strong components and the
    largest), the factorisation (new or reused; which kind; its CPU), the rest of the
    round (the solve, its two refinements and the greedy step) and the switches; per
    call of ``improve_ahead`` (the jump calls it for the policy's own bound, for every
    choice's and, where the check refuses, for the slowest choices' totals) its rounds
    and its look-ahead sweeps' CPU (the call's CPU outside its rounds).  Wraps
    ``policy_jump.lean_round`` where it exists, else ``policy_round`` (the base), and
    ``chain_factor`` where it exists, else ``topological.chain_lu``."""
    import numpy as np
    import scipy.sparse as sp
    from scipy.sparse import csgraph

    from mitld_lp.solvers import policy_jump, topological

    rounds: list[dict[str, Any]] = []
    calls: list[dict[str, Any]] = []
    made: list[tuple[str, float]] = []
    owner, name = ((policy_jump, "chain_factor") if hasattr(policy_jump, "chain_factor")
                   else (topological, "chain_lu"))
    factor = getattr(owner, name)

    def timed_factor(*a: Any, **k: Any) -> Any:
        c = _cpu()
        lu = factor(*a, **k)
        made.append((type(lu).__name__, _cpu() - c))
        return lu

    setattr(owner, name, timed_factor)
    rname = "lean_round" if hasattr(policy_jump, "lean_round") else "policy_round"
    step = getattr(policy_jump, rname)

    def timed_round(block: Any, inner: Any, reward: Any, chosen: Any, *a: Any) -> Any:
        chain = sp.csr_array(block.inner[chosen])
        n, label = csgraph.connected_components(chain, directed=True, connection="strong")
        made.clear()
        c = _cpu()
        v, t, nxt = step(block, inner, reward, chosen, *a)
        spent = _cpu() - c
        lu_s = sum(x for _, x in made)
        rounds.append({"call": len(calls) - 1, "states": int(block.states.size),
                       "entries": int(chain.nnz), "components": int(n),
                       "largest": int(np.bincount(label).max()),
                       "factor": made[0][0] if made else "reused", "factor_s": lu_s,
                       "rest_s": spent - lu_s,
                       "switches": int(np.count_nonzero(nxt != chosen))})
        return v, t, nxt

    setattr(policy_jump, rname, timed_round)
    improve = policy_jump.improve_ahead

    def timed_improve(*a: Any, **k: Any) -> Any:
        calls.append({"states": int(a[0].states.size), "allowed": len(a) > 3
                      and a[3] is not None or k.get("allowed") is not None})
        first = len(rounds)
        c = _cpu()
        calls[-1]["abandoned"] = True  # until it returns (a budgeted jump may stop)
        try:
            out = improve(*a, **k)
            calls[-1]["abandoned"] = False
        finally:
            mine = rounds[first:]
            calls[-1].update(total_s=_cpu() - c, rounds=len(mine), ahead_s=_cpu() - c - sum(
                r["factor_s"] + r["rest_s"] for r in mine))
        return out

    policy_jump.improve_ahead = timed_improve
    return rounds, calls


def _instrument(iteration: Any) -> _Split:
    """The iteration module's parts wrapped (names the base checkout may lack are
    skipped)."""
    from mitld_lp.solvers import kernels, topological

    split = _Split()
    split.wrap(iteration, "blocks", "blocks")
    split.wrap(iteration, "shared_levels", "levels")
    split.wrap(iteration, "breadth_first_order", "reach")
    split.wrap(iteration, "state_graph", "reach")
    split.wrap(iteration, "_result", "result")
    split.wrap(topological.SingleLevels, "solve", "singles")
    # Block.of runs before the gate: its CPU is held and given to the block it makes
    of = topological.Block.of

    def timed_of(q: Any, states: Any) -> Any:
        if split.depth:
            return of(q, states)
        c = _cpu()
        try:
            return of(q, states)
        finally:
            split.held += _cpu() - c

    topological.Block.of = staticmethod(timed_of)
    gate = iteration.use_compiled

    def gated(*args: Any) -> bool:
        loaded = kernels.kernel_loaded()
        c = _cpu()
        fast = gate(*args)
        spent = _cpu() - c
        c = _cpu()
        block = args[2] if len(args) > 2 else None
        entry = {"states": int(block.states.size) if block is not None else None,
                 "entries": int(args[1]), "route": "compiled" if fast else "numpy",
                 "sweeps": 0, "jumps": 0, "gate": spent, "block": split.held}
        split.held = 0.0
        entry.update(_gate_reason(args, loaded, fast))
        split.own += _cpu() - c
        split.blocks.append(entry)
        split.current = entry
        return fast

    iteration.use_compiled = gated
    split.wrap(iteration, "whole", "block")  # a jump's block with its moves out
    for name in ("value_order", "for_sweeps"):
        split.wrap(iteration, name, "order")
    split.wrap(iteration, "Prepared", "prepare")

    def swept(s: _Split, args: tuple, out: Any) -> None:
        if s.current is not None:
            s.current["sweeps"] += int(out[0])

    for name in ("compiled_sweeps", "numpy_sweeps"):
        split.wrap(iteration, name, "sweeps_cpu", swept)
    split.wrap(kernels, "excess", "stop_test")
    split.wrap(iteration, "excess", "stop_test")

    def jumped(s: _Split, args: tuple, out: Any) -> None:
        if s.current is not None:
            s.current["jumps"] += 1

    split.wrap(iteration, "jump", "jump", jumped)
    split.wrap(iteration, "_early_jump", "early_jump")
    return split


# ----------------------------------------------------------------------------- the runs


def _run_child(job: dict[str, Any], work: Path, library: Path | None) -> dict[str, Any]:
    (work / "job.json").write_text(json.dumps(job), encoding="utf-8")
    env = dict(os.environ)
    if library is not None:
        env["PYTHONPATH"] = os.pathsep.join(
            [str(library.resolve()), *filter(None, [os.environ.get("PYTHONPATH")])])
    else:
        env["PYTHONPATH"] = os.pathsep.join(
            [str(HERE.parent), *filter(None, [os.environ.get("PYTHONPATH")])])
    try:
        proc = subprocess.run([sys.executable, __file__, "--child", str(work)],
                              capture_output=True, text=True, timeout=BUDGET, env=env)
    except subprocess.TimeoutExpired:
        return {"error": f"over {BUDGET:.0f} s"}
    if proc.returncode != 0:
        return {"error": " ".join(proc.stderr.strip().splitlines()[-1:])}
    return json.loads((work / "split.json").read_text(encoding="utf-8"))


def _jobs(args: argparse.Namespace, work: Path) -> list[tuple[str, dict[str, Any]]]:
    import bench_qvbs as bq

    out: list[tuple[str, dict[str, Any]]] = []
    wanted = set(QUICK if args.quick else args.only or ())
    if wanted:
        if args.qvbs is None:
            raise SystemExit("iteration_sweeps.py: --qvbs DIR is needed for QVBS "
                             f"instances ({', '.join(sorted(wanted))})")
        found, _ = bq.jobs(args.qvbs, 0, bq.MAX_STATES, bq.FAMILIES, work)
        byname = {inst.name: job for inst, job in found}
        missing = sorted(wanted - set(byname))
        if missing:
            raise SystemExit(f"iteration_sweeps.py: --only: no such QVBS instance under "
                             f"{args.qvbs}: {', '.join(missing)}")
        out += [(name, dict(byname[name], repeats=args.repeats, routes=args.routes,
                            rounds=args.rounds))
                for name in sorted(wanted)]
    if args.bus and not args.quick:
        import bench_sweeps as bs
        from bench_scaling import Instance

        known = {Instance(*i).name: i for i in bs.FULL}
        unknown = sorted(set(args.bus) - set(known))
        if unknown:
            raise SystemExit(f"iteration_sweeps.py: --bus: no such instance of "
                             f"bench_sweeps.py: {', '.join(unknown)}")
        out += [(n, {"bus": list(known[n]), "repeats": args.repeats, "routes": args.routes,
                     "rounds": args.rounds})
                for n in args.bus]
    return out


def _f(x: Any, digits: int = 4) -> str:
    if x is None:
        return "-"
    if isinstance(x, float):
        return f"{x:.{digits}f}"
    return str(x)


def _rounds_report(r: dict[str, Any]) -> list[str]:
    """The ``--rounds`` table: one line a round, grouped by ``improve_ahead`` call."""
    if "rounds" not in r:
        return []
    calls, rounds = r["round_calls"], r["rounds"]
    lu = sum(x["factor_s"] for x in rounds)
    rest = sum(x["rest_s"] for x in rounds)
    ahead = sum(c["ahead_s"] for c in calls)
    lines = [f"policy jump's rounds: {len(calls)} improve_ahead calls, {len(rounds)} rounds, "
             f"{sum(x['factor'] != 'reused' for x in rounds)} factorisations "
             f"({_f(lu)} s), solves and greedy steps {_f(rest)} s, look-ahead sweeps "
             f"{_f(ahead)} s; whole run {_f(r['rounds_total_s'])} s (same bracket: "
             f"{r['rounds_same']})", "",
             "| call | states | round | chain entries | components (largest) | factor "
             "| factor_s | solve+greedy_s | switches |", "|---|---|---|---|---|---|---|---|---|"]
    seen: dict[int, int] = {}
    for x in rounds:
        seen[x["call"]] = seen.get(x["call"], 0) + 1
        call = calls[x["call"]]
        tag = (f"{x['call']}{' (allowed)' if call['allowed'] else ''}"
               f"{' (abandoned)' if call.get('abandoned') else ''}")
        lines.append(f"| {tag} | {x['states']} | {seen[x['call']]} | {x['entries']} "
                     f"| {x['components']} ({x['largest']}) | {x['factor']} "
                     f"| {_f(x['factor_s'])} | {_f(x['rest_s'])} | {x['switches']} |")
    return [*lines, ""]


def report(rows: list[dict[str, Any]]) -> str:
    lines = []
    for row in rows:
        for side in ("this", "base"):
            r = row.get(side)
            if r is None:
                continue
            head = f"## {row['name']} ({side})"
            if "error" in r:
                lines += [head, "", f"error: {r['error']}", ""]
                continue
            lines += [head, "",
                      f"quotient {r['quotient_states']:,} states, {r['quotient_entries']:,} "
                      f"entries, {r['models']} model(s); iteration_s {_f(r['iteration_s'])} "
                      f"(least of the plain runs), {r['sweeps']} sweeps, bracket "
                      f"[{r['lower']}, {r['upper_iter']}]; the solve's answer "
                      f"[{r['value']!r}, {r['upper']!r}], solve_cpu {_f(r['solve_cpu'])}",
                      f"split run {_f(r['split_total_s'])} s (same bracket: "
                      f"{r['split_same']}): " + ", ".join(
                          f"{k} {_f(v)}" for k, v in r["parts"].items())
                      + f", other {_f(r['other'])}", *(
                          f"{k}: iteration_s {_f(r[k]['iteration_s'])}, {r[k]['sweeps']} "
                          f"sweeps, bracket [{r[k]['bracket'][0]}, {r[k]['bracket'][1]}]"
                          for k in ("all_compiled", "all_numpy") if k in r), "",
                      "| block | states | entries | route | gate | gate_s | sweeps | sweeps_s "
                      "| ms/sweep | block_s | order_s | prepare_s | stop_test_s | jumps "
                      "| jump_s | early_jump_s |",
                      "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
            for i, b in enumerate(r["blocks"]):
                gate = b["rule"]
                if "depth" in b:
                    gate += (f" (depth {b['depth']}, numpy {b['numpy_work']:.3g}, "
                             f"compiled {b['compiled_work']:.3g})")
                per = (1e3 * b.get("sweeps_cpu", 0.0) / b["sweeps"]
                       if b["sweeps"] else None)
                lines.append(
                    f"| {i} | {b['states']} | {b['entries']} | {b['route']} | {gate} "
                    f"| {_f(b.get('gate'))} "
                    f"| {b['sweeps']} | {_f(b.get('sweeps_cpu'))} | {_f(per, 3)} "
                    f"| {_f(b.get('block'))} | {_f(b.get('order'))} "
                    f"| {_f(b.get('prepare'))} | {_f(b.get('stop_test'))} | {b['jumps']} "
                    f"| {_f(b.get('jump'))} | {_f(b.get('early_jump'))} |")
            lines.append("")
            lines += _rounds_report(r)
        if row.get("this") and row.get("base") and "error" not in row["this"] \
                and "error" not in row["base"]:
            a, b = row["this"], row["base"]
            lines += [f"{row['name']}: iteration_s {_f(b['iteration_s'])} -> "
                      f"{_f(a['iteration_s'])}, sweeps {b['sweeps']} -> {a['sweeps']}, "
                      f"same_bracket {a['brackets'] == b['brackets']}, same answer "
                      f"{(a['value'], a['upper']) == (b['value'], b['upper'])}", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, default=None, help="the QVBS checkout")
    ap.add_argument("--only", nargs="*", default=None, metavar="NAME",
                    help="QVBS instances (bench_qvbs.py's names)")
    ap.add_argument("--bus", nargs="*", default=(), metavar="NAME",
                    help="bench_sweeps.py's instances (e.g. bus_scaled_n64_d3)")
    ap.add_argument("--repeats", type=int, default=3, help="plain runs of the iteration")
    ap.add_argument("--compare", type=Path, default=None, metavar="DIR",
                    help="another checkout whose mitld_lp runs the same children")
    ap.add_argument("--routes", action="store_true",
                    help="also every block compiled, and none (after the plain runs)")
    ap.add_argument("--rounds", action="store_true",
                    help="also the policy jump's rounds one by one (after the split)")
    ap.add_argument("--quick", action="store_true", help="one small instance")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child is not None:
        work = Path(args.child)
        job = json.loads((work / "job.json").read_text(encoding="utf-8"))
        (work / "split.json").write_text(json.dumps(child_split(job)), encoding="utf-8")
        return 0
    if args.repeats < 1:
        raise SystemExit(f"iteration_sweeps.py: --repeats: at least 1, got {args.repeats}")
    if args.compare is not None and not (args.compare / "mitld_lp").is_dir():
        raise SystemExit(f"iteration_sweeps.py: --compare: no mitld_lp under {args.compare}")
    out = args.out or (HERE / "out" / "quick" if args.quick else HERE / "results")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        jobs = _jobs(args, work)
        if not jobs:
            raise SystemExit("iteration_sweeps.py: no instance: give --only, --bus or --quick")
        for name, job in jobs:
            row: dict[str, Any] = {"name": name, "this": _run_child(job, work, None)}
            if args.compare is not None:
                row["base"] = _run_child(job, work, args.compare)
            rows.append(row)
            print(report([row]), flush=True)
    out.mkdir(parents=True, exist_ok=True)
    _common.write_text(out / "iteration_sweeps.json", json.dumps(rows, indent=1))
    _common.write_text(out / "iteration_sweeps.md", report(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())

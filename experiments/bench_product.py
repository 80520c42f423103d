"""Benchmark: product construction throughput and memory on growing grids.

Each row: an n x n grid with three events -- one memoryless (geometric), two not (pmf
and Poisson, the latter truncated) -- and a task with a deadline (``--deadlines``)
after each event at a region in a different corner.  For each row, in the same run and
on the same model: the array construction (:func:`mitld_lp.product.product`) and its
peer, the first state-at-a-time construction (:mod:`mitld_lp.testing.reference_product`),
which must give the same MDP.  Printed: reachable states, transitions, wall and CPU
seconds of each (the CPU time of this process: on a shared machine the wall time varies
with the load), transitions per CPU second, the speed-up (wall, and CPU in parentheses),
and the peak memory per transition of the array construction (tracemalloc's peak during
a second build, divided by the transitions; numpy's buffers are traced).

Targets (issue 9): 3x the state-at-a-time construction, under 40 bytes per transition;
a 1e6-state product in under 20 s and under 1 GB.

Run: ``python experiments/bench_product.py [--sizes 16 32 64] [--deadlines 4 12]``;
``--quick`` runs two small rows.  The script prints its table and writes nothing.

``--prism MODEL.toml ...``: instead, the product of each model file's world (a
``[prism]`` world, as ``bench_qvbs.py`` writes them; loaded untimed) with its task's
automaton, its passes timed apart in CPU milliseconds (the least over ``--repeats``
builds): the automaton (``automaton``: to_dta and make_sta), the world's table read
into the layers (``layers``), the lean table levels' set-up (``lean_init``: the
automaton's steps tabulated, whether rows repeat a state), the levels' rows
(``expand``: the lean table levels, or the general expansion), the new states
numbered (``intern``, inside ``expand``; its dense-index part ``add_dense`` inside
it), the matrix assembled (``assemble``) and the rest of the build (``rest``); the
answer beside: the product's states, transitions and a digest of its arrays (the
same digest before and after a change: the same product).  ``compiled`` is the
compiled breadth-first loop's calls (:mod:`mitld_lp.product.bfs_kernels`), inside
``expand``'s place; ``first`` the first build's whole CPU (the compiled loop's load is
in it where the loop runs).  ``--levels numpy`` builds every level by NumPy,
``--levels compiled`` by the compiled loop from the first level on (its load paid
before the builds: ``kernel_loader.prepare()``), ``auto`` (the default) as the build
decides; a checkout without the loop ignores it.

    python experiments/bench_product.py --prism /tmp/jobs/*.toml --repeats 5
"""

from __future__ import annotations

import argparse
import time
import tracemalloc
from dataclasses import dataclass

import numpy as np

from mitld_lp.automata.sta import STA, make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.logic.parser import parse
from mitld_lp.mdp import MDP
from mitld_lp.model import bind_distributions
from mitld_lp.product import product
from mitld_lp.testing import reference_product
from mitld_lp.worlds.grid import GridWorld

SPEC = (
    "D[geometric(0.2)] a & D[pmf(0.1, 0.2, 0.3, 0.4)] b & D[poisson(3.0)] c"
    " & F(a & F[0,{d}] A) & F(b & F[0,{d}] B) & F(c & F[0,{d}] C)"
)


def world(n: int) -> GridWorld:
    return GridWorld.make(
        n, n, start=(n // 2, n // 2), slip=0.1,
        regions={"A": [(0, 0)], "B": [(n - 1, 0)], "C": [(0, n - 1)]},
    )


def task(deadline: int, epsilon: float) -> STA:
    spec = parse(SPEC.format(d=deadline))
    return make_sta(to_dta(spec), bind_distributions(spec), epsilon)


@dataclass(frozen=True, slots=True)
class Row:
    n: int
    deadline: int
    states: int
    transitions: int
    seconds: float
    cpu: float
    reference_seconds: float | None
    reference_cpu: float | None
    bytes_per_transition: float | None


def _same(a: MDP, b: MDP) -> bool:
    return (
        a.n_states == b.n_states
        and np.array_equal(a.row_groups, b.row_groups)
        and np.array_equal(a.matrix.indices, b.matrix.indices)
        and np.array_equal(a.matrix.data, b.matrix.data)
    )


def measure(n: int, deadline: int, epsilon: float, *, reference: bool, memory: bool) -> Row:
    game, sta = world(n), task(deadline, epsilon)
    t, c = time.perf_counter(), time.process_time()
    mdp = product(game, sta, progress=False)
    seconds, cpu = time.perf_counter() - t, time.process_time() - c
    ref_seconds = ref_cpu = None
    if reference:
        game, sta = world(n), task(deadline, epsilon)  # fresh caches: same work to do
        t, c = time.perf_counter(), time.process_time()
        ref = reference_product(game, sta)
        ref_seconds, ref_cpu = time.perf_counter() - t, time.process_time() - c
        if not _same(mdp, ref):
            raise SystemExit(f"{n}x{n}, deadline {deadline}: the two constructions differ")
        del ref
    per = None
    if memory:
        del mdp
        game, sta = world(n), task(deadline, epsilon)  # fresh caches
        tracemalloc.start()
        mdp = product(game, sta, progress=False)
        per = tracemalloc.get_traced_memory()[1] / max(mdp.n_transitions, 1)
        tracemalloc.stop()
    return Row(n, deadline, mdp.n_states, mdp.n_transitions, seconds, cpu, ref_seconds, ref_cpu,
               per)


PASSES = (("automaton", "mitld_lp.routes.stages", "to_dta"),
          ("automaton", "mitld_lp.routes.stages", "make_sta"),
          ("layers", "mitld_lp.product.build", "Layers"),
          ("lean_init", "mitld_lp.product.build", "Plain"),
          ("expand", "mitld_lp.product.table_levels.Plain", "expand"),
          ("expand", "mitld_lp.product.build", "_expand"),
          ("intern", "mitld_lp.product.build._Found", "intern"),
          ("add_dense", "mitld_lp.product.build._Found", "_add_dense"),
          ("assemble", "mitld_lp.product.build", "_assemble"),
          ("compiled", "mitld_lp.product.build", "run_compiled"))
"""Each pass: its column, where the function lives (a module, or a module's class) and
its name; a pass's CPU is summed over its calls."""


def _owner(where: str) -> object:
    import importlib

    try:
        return importlib.import_module(where)
    except ImportError:
        module, _, cls = where.rpartition(".")
        return getattr(importlib.import_module(module), cls)


def _levels(mode: str) -> None:
    """The levels' path (``--levels``): NumPy's, the compiled loop's, or the build's."""
    import importlib

    try:
        tl = importlib.import_module("mitld_lp.product.table_levels")
    except ImportError:
        return
    if mode != "auto" and hasattr(tl, "COMPILED"):
        tl.COMPILED = mode == "compiled"
        tl.COMPILED_MIN_STATES = 0 if mode == "compiled" else tl.COMPILED_MIN_STATES
        if mode == "compiled":  # the load paid before the builds (outside their times)
            from mitld_lp.util import kernel_loader

            kernel_loader.prepare()


def product_passes(model_file: str, repeats: int, levels: str = "auto") -> dict[str, object]:
    """The product of ``model_file``'s world and task, built ``repeats`` times: each
    pass's least CPU milliseconds, the whole build's, and the product's size and digest."""
    import functools
    import hashlib

    from mitld_lp import load_model
    from mitld_lp.routes.stages import build_posed
    from mitld_lp.synthesis import pose

    spent: dict[str, float] = {}

    def timed(column: str, f: object) -> object:
        @functools.wraps(f)  # type: ignore[arg-type]
        def run(*a: object, **k: object) -> object:
            c = time.process_time()
            try:
                return f(*a, **k)  # type: ignore[operator]
            finally:
                spent[column] = spent.get(column, 0.0) + time.process_time() - c
        return run

    _levels(levels)
    for column, where, name in PASSES:
        owner = _owner(where)
        if hasattr(owner, name):  # a pass this checkout does not have is left out
            setattr(owner, name, timed(column, getattr(owner, name)))
    model = load_model(model_file, max_states=2_000_000)
    best: dict[str, float] = {}
    first = None
    for _ in range(repeats):
        spent.clear()
        posed = pose(model)
        c = time.process_time()
        built = build_posed(posed, progress=False)
        spent["whole"] = time.process_time() - c
        first = spent["whole"] if first is None else first
        for k, v in spent.items():
            best[k] = min(best.get(k, float("inf")), v)
    mdp = built.mdp
    h = hashlib.sha256()
    for a in (mdp.row_groups, mdp.choice_actions, mdp.matrix.indptr, mdp.matrix.indices,
              mdp.matrix.data, mdp.target, mdp.sink, mdp.truncated):
        h.update(np.ascontiguousarray(a).tobytes())
    inner = sum(best.get(k, 0.0) for k in ("automaton", "layers", "lean_init", "expand", "compiled",
                                             "assemble"))
    return dict(states=mdp.n_states, transitions=mdp.n_transitions,
                digest=h.hexdigest()[:16], first=round((first or 0.0) * 1e3, 2),
                **{k: round(v * 1e3, 2) for k, v in best.items()},
                rest=round((best["whole"] - inner) * 1e3, 2))


def main_prism(files: list[str], repeats: int, levels: str = "auto") -> list[dict[str, object]]:
    """``--prism``: each model file's product passes, in a fresh process each."""
    import json
    import subprocess
    import sys

    rows = []
    for f in files:
        out = subprocess.run([sys.executable, __file__, "--prism-one", f, str(repeats), levels],
                             capture_output=True, text=True, check=True)
        row = dict(model=f.rsplit("/", 1)[-1], **json.loads(out.stdout.splitlines()[-1]))
        print(row, flush=True)
        rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> list[Row]:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two small rows (seconds)")
    ap.add_argument("--sizes", type=int, nargs="+", default=[16, 32, 64])
    ap.add_argument("--deadlines", type=int, nargs="+", default=[4, 12],
                    help="steps allowed after each event")
    ap.add_argument("--epsilon", type=float, default=0.01)
    ap.add_argument("--no-reference", action="store_true",
                    help="skip the state-at-a-time peer (for the largest rows)")
    ap.add_argument("--no-memory", action="store_true",
                    help="skip the tracemalloc build (it slows the build down)")
    ap.add_argument("--prism", nargs="+", default=None, metavar="MODEL",
                    help="the product passes of these model files' PRISM worlds instead")
    ap.add_argument("--repeats", type=int, default=3, help="builds of each (--prism)")
    ap.add_argument("--levels", choices=("auto", "numpy", "compiled"), default="auto",
                    help="the levels' path (--prism): as the build decides, NumPy's, compiled")
    args = ap.parse_args(argv)
    if args.prism:
        main_prism(args.prism, 1 if args.quick else args.repeats, args.levels)
        return []
    rows_wanted = [(8, 4), (16, 4)] if args.quick else [
        (n, d) for d in args.deadlines for n in args.sizes
    ]
    print(f"{'grid':>7} {'T':>3} {'states':>10} {'transitions':>12} {'seconds':>8} "
          f"{'cpu s':>7} {'trans/cpu s':>11} {'ref s':>8} {'ref cpu s':>9} "
          f"{'ref trans/cpu s':>15} {'speed-up (cpu)':>14} {'B/trans':>8}")
    rows = []
    for n, d in rows_wanted:
        r = measure(n, d, args.epsilon, reference=not args.no_reference,
                    memory=not args.no_memory)
        rows.append(r)
        rate = r.transitions / r.cpu
        if r.reference_seconds is None or r.reference_cpu is None:
            ref = f"{'-':>8} {'-':>9} {'-':>15} {'-':>14}"
        else:
            ref = (f"{r.reference_seconds:>8.2f} {r.reference_cpu:>9.2f} "
                   f"{r.transitions / r.reference_cpu:>15,.0f} "
                   f"{r.reference_seconds / r.seconds:>5.1f}x ({r.reference_cpu / r.cpu:.1f}x)")
        per = "-" if r.bytes_per_transition is None else f"{r.bytes_per_transition:.1f}"
        print(f"{n:>3}x{n:<3} {d:>3} {r.states:>10,} {r.transitions:>12,} {r.seconds:>8.2f} "
              f"{r.cpu:>7.2f} {rate:>11,.0f} {ref} {per:>8}", flush=True)
    return rows


if __name__ == "__main__":
    import json
    import sys

    if sys.argv[1:2] == ["--prism-one"]:  # main_prism's child
        print(json.dumps(product_passes(sys.argv[2], int(sys.argv[3]), *sys.argv[4:5])))
    else:
        main()

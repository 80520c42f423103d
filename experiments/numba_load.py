"""What a process pays to load numba and the compiled kernels, part by part.

Each round is a fresh process (``--rounds``, default 5) that imports NumPy, SciPy's
sparse matrices and ``scipy.linalg`` (loaded by every solve of a product large enough to
sweep with the kernel), then times in CPU seconds: ``import numba``; the typing
context's registries; the CPU target's registries (numba refreshes them before loading
any kernel from its disk cache, :func:`numba.core.caching` ``load_overload``); the
first call of a graph kernel (:func:`mitld_lp.solvers.compiled_graph.end_components_among`,
the first kernel the analysis of a large product asks for; its end components of a
two-state block printed beside); the first call of the block kernel
(:func:`mitld_lp.solvers.kernels.compiled_sweeps`, its load from the cache and its run
on the same block: its bracket of 1/2 is printed beside); and the first call of one
level kernel.  The kernels must be in the disk cache (run the script twice after a
change: the first run compiles them).  Prints the median and least of each part::

    python experiments/numba_load.py

Two sets of rounds take turns: ``whole`` (:data:`mitld_lp.solvers.numba_narrow.ENABLED`
set to False: numba's own load, as a process that asked for a graph kernel first had
before every compiled module put the narrow load in place) and ``narrow`` (what every
compiled module does since: the target's registries are not refreshed, and the first
call loads the kernel with numba's runtime only).  The answers must be the same to the
bit in both.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys

CHILD = r"""
import json, time
c = time.process_time
import numpy as np, scipy.sparse as sp, scipy.linalg  # noqa: F401
t = [c()]
import numba  # noqa: F401
t.append(c())
if NARROW:
    from mitld_lp.solvers import numba_narrow
    assert numba_narrow.install()
    t += [c(), c()]
else:
    from mitld_lp.solvers import numba_narrow
    numba_narrow.ENABLED = False  # every compiled module would put it in place
    from numba.core.registry import cpu_target
    cpu_target.typing_context.refresh()
    t.append(c())
    cpu_target.target_context.refresh()
    t.append(c())
inner = sp.csr_array(np.array([[0.0, 0.5], [0.5, 0.0]]))
from mitld_lp.solvers import compiled_graph
alive, allowed, label = compiled_graph.end_components_among(
    inner.indptr, inner.indices, inner.data > 0, np.array([0, 1, 2]), np.arange(2))
t.append(c())
from mitld_lp.solvers import kernels
prep = kernels.Prepared(inner, np.array([0, 1, 2]))
local = np.column_stack([np.zeros(2), np.ones(2)])
kernels.compiled_sweeps(prep, np.full((2, 2), 0.25), local, 1e-12, 1000)
t.append(c())
from mitld_lp.solvers import level_kernels
x = np.zeros((2, 1))
diag = np.zeros(2)
diag.flags.writeable = False  # the types the solver passes: no signature of its own
level_kernels.chain_solve(np.arange(2), inner.indptr.astype(np.int64),
                          inner.indices.astype(np.int64), inner.data, diag, np.ones((2, 1)), x)
t.append(c())
parts = [b - a for a, b in zip(t, t[1:])]
print(json.dumps({"parts": parts, "answer": [float(local[0, 0]).hex(), float(local[0, 1]).hex()],
                  "components": [alive.tolist(), label.tolist()]}))
"""

NAMES = ("import numba", "typing registries", "target registries",
         "graph kernel, first call", "block kernel, first call", "a level kernel, first call")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=5, help="fresh processes (default 5)")
    ap.add_argument("--quick", action="store_true",
                    help="one round (it prints only: no file is written either way)")
    args = ap.parse_args(argv)
    if args.quick:
        args.rounds = 1
    runs: dict[bool, list[dict]] = {False: [], True: []}
    for _ in range(args.rounds):  # the two loads taking turns
        for narrow in (False, True):
            done = subprocess.run([sys.executable, "-c", f"NARROW = {narrow}\n" + CHILD],
                                  text=True, capture_output=True)
            if done.returncode:
                sys.exit(f"the child failed:\n{done.stderr}")
            runs[narrow].append(json.loads(done.stdout.strip().splitlines()[-1]))
    answers = {tuple(r["answer"]) for rs in runs.values() for r in rs}
    if len(answers) != 1:
        sys.exit(f"the loads' brackets differ: {answers}")
    comps = {json.dumps(r["components"]) for rs in runs.values() for r in rs}
    if len(comps) != 1:
        sys.exit(f"the loads' end components differ: {comps}")
    low, high = (float.fromhex(x) for x in answers.pop())
    print(f"block kernel's bracket on the two-state block, both loads: [{low:.12f}, "
          f"{high:.12f}] (exact 1/2: x = 1/4 + x/2)")
    print(f"graph kernel's end components of the two-state block, both loads (alive, "
          f"label): {comps.pop()} (one end component of both states)")
    print(f"{'part':<28} {'whole: median s':>15} {'least s':>8} {'narrow: median s':>17} "
          f"{'least s':>8}")
    for i, name in enumerate((*NAMES, "total")):
        cells = []
        for narrow in (False, True):
            xs = [sum(r["parts"]) if name == "total" else r["parts"][i]
                  for r in runs[narrow]]
            cells.append(f"{statistics.median(xs):{17 if narrow else 15}.3f} {min(xs):8.3f}")
        print(f"{name:<28} {cells[0]} {cells[1]}")


if __name__ == "__main__":
    main()

"""A compiled block's sweeps one by one: why it takes the sweeps it takes.

Per instance, in this process: the solve runs once with the interval iteration's call
captured, then the call runs again with the first compiled block's sweeps captured (its
matrix, exit rewards and starting bounds; with ``compiled=True`` where the gate swept
none compiled).  On that block, one sweep a call (the kernel keeps its state between
calls, so the sweeps are the iteration's):

* per sweep: the largest gap over ``tol`` (``over``), the kernel's phase (0 watching, 1
  verifying a guess, -1 plain), the states whose upper bound is still within 1e-3 of 1,
  and each side's largest error against a reference (the same block swept plainly to a
  gap of 1e-15: sound bounds, so their midpoint is within 1e-15 of the optimum);
* the sweeps and least CPU (of ``--repeats``) to close the block with the guesses (the
  default) and without them (plain sweeps), each with a digest of the final bounds;
* the sweeps in three other orders: forward, and by distance (backwards) to the states
  whose upper bound a sweep from 1 lowers by more than 0.5 ("leak").

::

    python experiments/sweep_trace.py --qvbs /work/shared/qvbs \\
        --only zeroconf.1000-4-false.correct_max zeroconf.1000-4-false.correct_min
    python experiments/sweep_trace.py --qvbs /work/shared/qvbs --quick

The answer of each instance's solve is printed beside its figures.  ``--quick``: one
small QVBS instance (its block swept compiled), written to ``experiments/out/quick``
(or ``--out``).  Written: ``sweep_trace.md``.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

QUICK = ("consensus.2-2.c2",)


def _capture(name: str, qvbs: Path) -> tuple[Any, dict[str, Any]]:
    """The instance's solve, and its first compiled block as the kernel received it."""
    import bench_qvbs as bq
    import iteration_sweeps as its

    found, _ = bq.jobs(qvbs, 0, bq.MAX_STATES, bq.FAMILIES, Path(tempfile.mkdtemp()))
    job = {inst.name: j for inst, j in found}[name]
    model = its._model(job)
    from mitld_lp import synthesize
    from mitld_lp.solvers import iteration

    plain = iteration.interval_iterations
    calls: list[tuple[tuple, dict]] = []
    iteration.interval_iterations = lambda *a, **k: calls.append((a, k)) or plain(*a, **k)
    try:
        r = synthesize(model)
    finally:
        iteration.interval_iterations = plain
    block: dict[str, Any] = {}
    real = iteration.compiled_sweeps

    def spy(prep, exits, local, tol, max_sweeps, sense, precision=None):
        if not block:
            block.update(inner=prep.inner.copy(), groups=prep.groups.copy(),
                         exits=np.array(exits), local=local.copy(), sense=sense, tol=tol)
        return real(prep, exits, local, tol, max_sweeps, sense, precision)

    iteration.compiled_sweeps = spy
    try:
        a, k = calls[0]
        plain(*a, **k)
        if not block:
            plain(*a, **dict(k, compiled=True))
    finally:
        iteration.compiled_sweeps = real
    return r, block


def _run(b: dict[str, Any], optimistic: bool, order: np.ndarray | None = None,
         tol: float | None = None, each: Any = None) -> tuple[int, np.ndarray, Any]:
    from mitld_lp.solvers import kernels

    n = b["groups"].size - 1
    prep = kernels.Prepared(b["inner"], b["groups"])
    if order is not None:
        prep.order = order
    if not optimistic:
        prep.guess = np.zeros_like(b["local"])
        prep.track = np.zeros(8 + 6 * b["local"].shape[1])
        prep.track[0] = -1.0
    local = b["local"].copy()
    done = 0
    while done < 20_000:
        swept, over = kernels.compiled_sweeps(prep, b["exits"], local,
                                              tol or b["tol"], 1 if each else 16,
                                              b["sense"], None)
        done += swept
        if each is not None:
            each(done, over, prep, local)
        if over < 1.0 or swept == 0:
            break
    del n
    return done, local, prep


def _leak_order(b: dict[str, Any]) -> np.ndarray:
    """States by distance (backwards inside the block) to those whose upper bound one
    update from all ones lowers by more than 0.5; the rest last, last state first."""
    from scipy.sparse.csgraph import breadth_first_order

    inner, groups = b["inner"], b["groups"]
    n = groups.size - 1
    owner = np.repeat(np.arange(n), np.diff(groups))
    loop = np.zeros(inner.shape[0])
    diag = inner.indices == owner[np.repeat(np.arange(inner.shape[0]), np.diff(inner.indptr))]
    np.add.at(loop, np.repeat(np.arange(inner.shape[0]), np.diff(inner.indptr))[diag],
              inner.data[diag])
    one = (b["exits"][:, 1] + inner @ np.ones(n) - loop) / np.where(loop < 1, 1 - loop, 1)
    best = b["sense"].reduce(one[:, None], groups[:-1])[:, 0]
    seeds = np.flatnonzero(1 - best > 0.5)
    moves = sp.csr_array((np.ones(inner.nnz), inner.indices, inner.indptr[groups]),
                         shape=(n, n))
    back = sp.bmat([[moves.T, None], [sp.csr_array((np.ones(seeds.size),
                    (np.zeros(seeds.size, int), seeds)), shape=(1, n)), None]]).tocsr()
    back.resize((n + 1, n + 1))
    found = breadth_first_order(back, n, directed=True, return_predecessors=False)[1:]
    rest = np.setdiff1d(np.arange(n), found)[::-1]
    return np.concatenate([found, rest]).astype(np.int64)


def trace(name: str, qvbs: Path, repeats: int) -> list[str]:
    r, b = _capture(name, qvbs)
    n = b["groups"].size - 1
    out = [f"## {name}", "",
           f"answer [{r.lower!r}, {r.upper!r}]; block {n:,} states, "
           f"{b['inner'].shape[0]:,} choices, {b['inner'].nnz:,} entries, {b['sense']}", ""]
    _, ref, _ = _run(b, False, tol=1e-15)
    v = ref.mean(axis=1)
    rows = ["| sweep | over | phase | upper held near 1 | upper error | lower error |",
            "|---|---|---|---|---|---|"]

    def each(done, over, prep, local):
        rows.append(f"| {done} | {over:.3g} | {prep.track[0]:.0f} | "
                    f"{int(np.sum(local[:, 1] > 1 - 1e-3) - np.sum(v > 1 - 1e-3))} | "
                    f"{float(np.max(local[:, 1] - v)):.2e} | "
                    f"{float(np.max(v - local[:, 0])):.2e} |")

    _run(b, True, each=each)
    out += rows + [""]
    out += ["| order | optimistic | sweeps | least CPU s | digest |", "|---|---|---|---|---|"]
    for optimistic in (True, False):
        best = np.inf
        for _ in range(repeats):
            c = time.process_time()
            done, local, _ = _run(b, optimistic)
            best = min(best, time.process_time() - c)
        digest = hashlib.sha1(local.tobytes()).hexdigest()[:12]
        out.append(f"| default order | {optimistic} | {done} | {best:.4f} | {digest} |")
    for label, order in (("forward", np.arange(n, dtype=np.int64)),
                         ("by distance to the leaks", _leak_order(b))):
        done, _, _ = _run(b, True, order=order)
        out.append(f"| {label} | True | {done} | | |")
    return out + [""]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--qvbs", type=Path, required=True, help="the QVBS checkout")
    ap.add_argument("--only", nargs="*", default=[], help="QVBS instances (bench_qvbs's names)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="one small instance")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    names = list(QUICK) if args.quick else args.only
    out_dir = args.out or (HERE / "out" / ("quick" if args.quick else "sweep_trace"))
    out_dir.mkdir(parents=True, exist_ok=True)
    lines = []
    for name in names:
        part = trace(name, args.qvbs, 1 if args.quick else args.repeats)
        print("\n".join(part), flush=True)
        lines += part
    (out_dir / "sweep_trace.md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

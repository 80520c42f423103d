"""The block kernel's sweeps before and after a change of its helpers, in one process.

Loads ``mitld_lp/solvers/compiled_kernels.py`` from this checkout and from another one
(``--compare DIR``, a ``git archive`` of the base commit) as two modules, and sweeps the
same random block with each, in turns (so the machine's noise hits both):

* ``plain``: a fixed number of plain sweeps (no guesses: ``track[0] = -1``), CPU
  seconds per sweep;
* ``optimistic``: the solver's default, guesses watched and verified, from ``[0, 1]``
  until every gap is below ``--tol``, calls of ``--chunk`` sweeps as the solver makes;
  the sweeps (verifying ones among them) and the CPU seconds per sweep.

For one model (two columns: the scalar path) and two (four: the general path), maximum.
The bounds, guesses, kernel state and sweep counts of the two checkouts must be equal to
the bit (printed: ``same``); the answer (the bracket at the block's first state) is
printed beside every time.  Each kernel is called once before the timing (its compile or
its load is not timed); they are compiled into a scratch numba cache of the run's own,
as their module names are not the package's (an entry cached under such a name cannot
be loaded by the package)::

    python experiments/sweep_sigs_speed.py --compare /tmp/base --states 200000
"""

from __future__ import annotations

import argparse
import atexit
import importlib.util
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp


def _load(root: Path, name: str):
    path = root / "mitld_lp" / "solvers" / "compiled_kernels.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def block(n: int, seed: int):
    """``n`` states, two choices each, three successors a choice (one a ring step, two
    anywhere), goal and fail exits of 1e-3 to 3e-3 a choice: slow to close by plain
    sweeps, so the guesses are verified."""
    rng = np.random.default_rng(seed)
    choices = 2 * n
    owner = np.repeat(np.arange(n), 2)
    succ = np.stack([(owner + 1) % n, rng.integers(0, n, choices), rng.integers(0, n, choices)],
                    axis=1)
    exits = rng.uniform(1e-3, 3e-3, (choices, 2))
    w = rng.uniform(0.2, 1.0, (choices, 3))
    w *= ((1.0 - exits.sum(axis=1)) / w.sum(axis=1))[:, None]
    inner = sp.csr_array((w.ravel(), (np.repeat(np.arange(choices), 3), succ.ravel())),
                         shape=(choices, n))
    inner.sum_duplicates()
    return inner, np.arange(0, choices + 1, 2, dtype=np.int64), exits


def sweep(kern, prep, exits, optimistic: bool, sweeps: int, tol: float, chunk: int):
    """One run of ``kern`` from ``[0, 1]``: (CPU s, sweeps, bounds, guesses, track)."""
    from mitld_lp.solvers import kernels

    k = exits.shape[1]
    local = np.tile([0.0, 1.0], (prep.groups.size - 1, k // 2))
    guess = np.zeros_like(local)
    track = kernels._new_track(k, optimistic)
    indptr, indices = prep.index
    # a checkout from sweep-86b on takes the listed exit rows: its general route here
    more = (np.empty(0, np.int64), False, True) if kern.py_func.__code__.co_argcount > 15 else ()
    done, over = 0, np.inf
    t0 = time.process_time()
    while done < sweeps and over >= 1.0:
        step = min(chunk, sweeps - done)
        swept, over = kern(indptr, indices, prep.inner.data, prep.groups, prep.leave, exits,
                           local, prep.order, step, tol if optimistic else 1e-300, False, -1.0,
                           kernels.FLOOR, guess, track, *more)
        done += swept
    return time.process_time() - t0, done, local, guess, track


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--compare", type=Path, required=True, help="the 'before' checkout")
    ap.add_argument("--states", type=int, default=200_000)
    ap.add_argument("--plain-sweeps", type=int, default=40)
    ap.add_argument("--tol", type=float, default=1e-6)
    ap.add_argument("--chunk", type=int, default=64, help="sweeps a kernel call")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--quick", action="store_true",
                    help="a block of 2,000 states, one round (it prints only)")
    args = ap.parse_args(argv)
    if args.quick:
        args.states, args.rounds = 2_000, 1
    scratch = tempfile.mkdtemp(prefix="sweep-sigs-speed-")
    atexit.register(shutil.rmtree, scratch, ignore_errors=True)
    os.environ["NUMBA_CACHE_DIR"] = scratch  # numba reads it when first imported, below
    here = Path(__file__).resolve().parent.parent
    from mitld_lp.solvers import kernels

    kerns = {"before": _load(args.compare.resolve(), "before_kernels").gauss_seidel,
             "after": _load(here, "after_kernels").gauss_seidel}
    inner, groups, exits2 = block(args.states, 1)
    prep = kernels.Prepared(inner, groups)
    print(f"block: {args.states} states, {inner.nnz} entries; tol {args.tol}, chunk "
          f"{args.chunk}; {args.rounds} rounds, before and after in turns; CPU s")
    for models in (1, 2):
        exits = np.ascontiguousarray(exits2[:, [m for m in range(models) for _ in range(2)]])
        for mode, optimistic, sweeps in (("plain", False, args.plain_sweeps),
                                         ("optimistic", True, 100_000)):
            times: dict[str, list[float]] = {"before": [], "after": []}
            runs: dict = {}
            for kern in kerns.values():  # compile or load, untimed
                sweep(kern, prep, exits, optimistic, 2, args.tol, 2)
            for _ in range(args.rounds):
                for label, kern in kerns.items():
                    cpu, done, local, guess, track = sweep(kern, prep, exits, optimistic,
                                                           sweeps, args.tol, args.chunk)
                    times[label].append(cpu / done)
                    runs[label] = (done, local, guess, track)
            b, a = runs["before"], runs["after"]
            same = b[0] == a[0] and all(np.array_equal(x, y)
                                        for x, y in zip(b[1:], a[1:], strict=True))
            med = {k: statistics.median(v) for k, v in times.items()}
            ratios = [x / y for x, y in zip(times["after"], times["before"], strict=True)]
            done, local, _, track = a
            print(f"{models} model(s) {mode:<10} sweeps {done:>5} (verifying {int(track[6]):>4})"
                  f"  state 0: [{local[0, 0]:.12g}, {local[0, 1]:.12g}]  ms/sweep before "
                  f"{1e3 * med['before']:.3f} after {1e3 * med['after']:.3f} "
                  f"(after/before {med['after'] / med['before']:.3f}; each round "
                  f"{' '.join(f'{r:.3f}' for r in ratios)})"
                  f"  same: {same}")


if __name__ == "__main__":
    main()

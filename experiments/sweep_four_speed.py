"""The compiled block sweeps on two models (four columns) timed alone: a random block of
``--states`` states (1-3 choices a state, 2-6 entries a choice, a self-loop on some,
each choice leaving to a goal and to failure), both models (reaching the goal,
reaching failure) swept by :func:`mitld_lp.solvers.kernels.compiled_sweeps` until
closed, in chunks of 16 sweeps as the iteration calls them; the least CPU of
``--repeats`` solves, the sweeps, the verifying sweeps and a SHA-256 of the final bounds
(the same digest on two checkouts: the same bits).  Run it with each checkout's
``PYTHONPATH`` (its kernels compiled first: run it twice)::

    PYTHONPATH=<tree> python experiments/sweep_four_speed.py --states 200000
"""

from __future__ import annotations

import argparse
import hashlib
import time

import numpy as np
import scipy.sparse as sp


def block(n: int, seed: int) -> tuple[sp.csr_array, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    choices = rng.integers(1, 4, size=n)
    groups = np.concatenate([[0], np.cumsum(choices)])
    m = int(groups[-1])
    owner = np.repeat(np.arange(n), choices)
    width = rng.integers(2, 7, size=m)
    rows = np.repeat(np.arange(m), width)
    cols = (np.repeat(owner, width) + rng.integers(-50, 50, size=rows.size)) % n
    vals = rng.random(rows.size) + 0.05
    exit_mass = rng.random((m, 2)) * 0.02 + 0.0005
    scale = np.bincount(rows, weights=vals, minlength=m)
    vals = vals / scale[rows] * (1.0 - exit_mass.sum(axis=1))[rows]
    inner = sp.csr_array((vals, (rows, cols)), shape=(m, n))
    inner.sum_duplicates()
    return inner, groups, exit_mass


def main() -> None:
    from mitld_lp.solvers import kernels
    from mitld_lp.solvers.graph import Sense

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--states", type=int, default=200_000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--min", action="store_true", help="minimise (default: maximise)")
    args = ap.parse_args()
    inner, groups, exit_mass = block(args.states, 3)
    cols = np.ascontiguousarray(np.repeat(exit_mass, 2, axis=1))
    sense = Sense.MIN if args.min else Sense.MAX
    best, out = np.inf, None
    for _ in range(args.repeats):
        prep = kernels.Prepared(inner, groups)
        _ = prep.index
        local = np.tile([0.0, 1.0], (args.states, 2))
        t0 = time.process_time()
        done, over = 0, np.inf
        while over >= 1.0 and done < 100_000:
            swept, over = kernels.compiled_sweeps(prep, cols, local, 1e-10, 16, sense)
            done += swept
        cpu = time.process_time() - t0
        if cpu < best:
            best = cpu
        out = (done, int(prep.track[6]), hashlib.sha256(local.tobytes()).hexdigest()[:16],
               local[0].tolist())
    print(f"cpu {best:.4f} s  sweeps {out[0]}  verifying {out[1]}  "
          f"ms/sweep {1000 * best / out[0]:.3f}  digest {out[2]}  state 0 {out[3]}")


if __name__ == "__main__":
    main()

"""Profile: the chain's never / sure sets by three routes, on a solve's own inputs.

The certificate's chain (:func:`mitld_lp.solvers.certify_chain.chain`) finds the states
of a policy's chain with no path to the target (``never``) and those with no path to
``never`` (``sure``).  The solve's compiled route
(:func:`mitld_lp.solvers.certify_kernels.chain_sets`) reverses the policy's edges by a
counting sort and searches the reversal twice.  Two routes that read the policy's own
rows forward, with no reversal, are written here (not in the package) and timed beside
it on the inputs captured from each instance's certificate:

* ``sweeps``: the two least fixed points (reaches the target; reaches ``never``) by
  sweeps over the states in decreasing index order until nothing changes (PRISM's
  breadth-first numbering puts most successors after their state);
* ``tarjan``: one iterative depth-first search (Tarjan's components), each component's
  two flags settled when it closes from its members' edges into closed components.

Every route's sets are compared with the solve's (``same``).  CPU ms, the least of
``--rounds``.  ``--quick``: one random model made here, no QVBS (seconds).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import _common
import numba
import numpy as np
import scipy.sparse as sp

HERE = Path(__file__).resolve().parent


@numba.njit(cache=False)
def _closure(states, rows, indptr, indices, data, seed):  # pragma: no cover - compiled
    """The states with a path to a ``seed`` state along the positive entries of row
    ``rows[i]`` out of ``states[i]``: sweeps in decreasing order until none changes;
    returns the set and the sweeps run."""
    reach = seed.copy()
    sweeps = 0
    changed = True
    while changed:
        sweeps += 1
        changed = False
        for i in range(states.shape[0] - 1, -1, -1):
            if not reach[states[i]]:
                r = rows[i]
                for e in range(indptr[r], indptr[r + 1]):
                    if data[e] > 0.0 and reach[indices[e]]:
                        reach[states[i]] = changed = True
                        break
    return reach, sweeps


def sweeps_sets(states, rows, indptr, indices, data, target):
    """``(never, sure, sweeps)`` by :func:`_closure` twice."""
    reach, k1 = _closure(states, rows, indptr, indices, data, target)
    never = ~reach
    bad, k2 = _closure(states, rows, indptr, indices, data, never)
    return never, ~bad, (k1, k2)


@numba.njit(cache=False)
def _tarjan(states, rows, indptr, indices, data, target):  # pragma: no cover - compiled
    """Per state, bit 0: a path to the target, bit 1: a path to a state without one;
    by one iterative Tarjan search over the chain's edges.  A state put on the call
    stack is entered (numbered, stacked, flagged) at the top of the loop."""
    n = target.shape[0]
    rowof = np.full(n, -1, dtype=np.int64)
    for i in range(states.shape[0]):
        rowof[states[i]] = rows[i]
    index = np.full(n, -1, dtype=np.int32)
    low = np.empty(n, dtype=np.int32)
    flag = np.zeros(n, dtype=np.uint8)  # bits 0, 1 as above; 4: on the stack
    stack = np.empty(n, dtype=np.int32)
    call = np.empty(n, dtype=np.int32)
    edge = np.empty(n, dtype=np.int64)  # each call's next entry; -1: not entered
    counter = 0
    top = 0
    for root in range(n):
        if index[root] >= 0:
            continue
        cp = 0
        call[0] = root
        edge[0] = -1
        while cp >= 0:
            s = call[cp]
            r = rowof[s]
            if edge[cp] < 0:
                index[s] = low[s] = counter
                counter += 1
                stack[top] = s
                top += 1
                flag[s] = 5 if target[s] else 4
                edge[cp] = indptr[r] if r >= 0 else 0
            e = edge[cp]
            end = indptr[r + 1] if r >= 0 else 0
            while e < end and (not data[e] > 0.0 or index[indices[e]] >= 0):
                t = indices[e]
                if data[e] > 0.0:  # seen: on the stack (a back edge) or closed
                    if flag[t] & 4:
                        low[s] = min(low[s], index[t])
                    else:
                        flag[s] |= flag[t] & 3
                e += 1
            if e < end:  # a new state: called
                edge[cp] = e + 1
                cp += 1
                call[cp] = indices[e]
                edge[cp] = -1
                continue
            if low[s] == index[s]:  # a component closes: its flags settled together
                acc = 0
                k = top
                while True:
                    k -= 1
                    acc |= flag[stack[k]] & 3
                    if stack[k] == s:
                        break
                if not acc & 1:
                    acc |= 2
                for q in range(k, top):
                    flag[stack[q]] = acc
                top = k
            cp -= 1
            if cp >= 0:
                par = call[cp]
                low[par] = min(low[par], low[s])
                flag[par] |= flag[s] & 3
    return flag


def tarjan_sets(states, rows, indptr, indices, data, target):
    flag = _tarjan(states, rows, indptr, indices, data, target)
    return (flag & 1) == 0, (flag & 2) == 0, None


def solve_sets(states, rows, indptr, indices, data, target):
    from mitld_lp.solvers.certify_kernels import chain_sets

    n = target.shape[0]
    never, sure = np.empty(n, dtype=bool), np.empty(n, dtype=bool)
    chain_sets(states, rows, indptr, indices, data, target.copy(), never, sure)
    return never, sure, None


ROUTES = {"reversal (solve)": solve_sets, "sweeps": sweeps_sets, "tarjan": tarjan_sets}


def captured(job: dict[str, Any]) -> tuple[sp.csr_array, np.ndarray, np.ndarray]:
    """The matrix, target and policy of the first chain a synthesis of ``job`` solves."""
    import cert_stages

    import mitld_lp.solvers.certify as cf
    from mitld_lp import synthesize

    model = cert_stages._load_model(job)
    got: list[Any] = []
    original = cf.chain

    def wrapper(mdp: Any, target: Any, policy: Any, *a: Any, **k: Any) -> Any:
        got.append((sp.csr_array(mdp.matrix), np.array(target, dtype=bool),
                    np.array(policy, dtype=np.int64)))
        return original(mdp, target, policy, *a, **k)

    cf.chain = wrapper
    try:
        synthesize(model)
    finally:
        cf.chain = original
    return got[0]


def random_chain(seed: int = 7, n: int = 20_000) -> tuple[sp.csr_array, np.ndarray, np.ndarray]:
    """A random chain with cycles (``--quick``): three successors a state, one in ten
    states a target, one in twenty absorbing."""
    rng = np.random.default_rng(seed)
    cols = rng.integers(0, n, size=(n, 3))
    m = sp.csr_array((np.full(3 * n, 1 / 3), cols.ravel(), np.arange(0, 3 * n + 1, 3)),
                     shape=(n, n))
    target = rng.random(n) < 0.1
    policy = np.where(rng.random(n) < 0.05, -1, np.arange(n))
    return m, target, policy


def measure(name: str, got: tuple[sp.csr_array, np.ndarray, np.ndarray], rounds: int,
            ) -> list[list[Any]]:
    m, target, policy = got
    states = np.flatnonzero((policy >= 0) & ~target).astype(np.int64)
    rows = policy[states].astype(np.int64)
    args = (states, rows, m.indptr, m.indices, m.data, target)
    ref = solve_sets(*args)
    out = []
    for route, f in ROUTES.items():
        f(*args)  # compiled / linked first
        best = float("inf")
        for _ in range(rounds):
            c = time.process_time()
            got_sets = f(*args)
            best = min(best, time.process_time() - c)
        same = bool(np.array_equal(got_sets[0], ref[0]) and np.array_equal(got_sets[1], ref[1]))
        out.append([name, route, f"{1e3 * best:.2f}", same, got_sets[2],
                    int(ref[0].sum()), int(ref[1].sum()), int(m.indptr[rows + 1].sum()
                                                                 - m.indptr[rows].sum())])
    return out


def main(argv: list[str] | None = None) -> int:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, help="a checkout's benchmarks/ of ahartmanns/qcomp")
    ap.add_argument("--only", nargs="*", default=[])
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args(argv)
    out = _common.out_dir(args)
    rows: list[list[Any]] = []
    if args.quick or args.qvbs is None:
        rows += measure("random 20,000", random_chain(), 3 if args.quick else args.rounds)
    if args.qvbs is not None and not args.quick:
        import bench_qvbs as bq

        with tempfile.TemporaryDirectory(prefix="chain_routes_") as tmp:
            found = bq.jobs(args.qvbs, 0, bq.MAX_STATES, bq.FAMILIES, Path(tmp))[0]
            for inst, job in found:
                if inst.name in set(args.only):
                    rows += measure(inst.name, captured(job), args.rounds)
    head = ["instance", "route", "cpu_ms", "same", "sweeps", "never", "sure", "row_entries"]
    text = "\n".join(["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
                     + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]) + "\n"
    print(text)
    _common.write_text(out / "chain_routes.md", text)
    return 0


if __name__ == "__main__":
    sys.exit(main())

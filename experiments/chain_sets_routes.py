"""Measured and not kept (cert-86): the certificate chain's ``never`` / ``sure`` sets by one
forward depth-first search instead of the edges reversed and searched twice.

Per QVBS instance (posed as ``bench_qvbs.py`` poses it): one synthesis with the chain's
arguments recorded (the policy's rows of the acting states, the target), then the
package's kernel (:func:`mitld_lp.solvers.certify_kernels.chain_sets`: a counting-sort
reversal and two breadth-first searches) and this script's depth-first search
(:func:`dfs_sets`, compiled here with plain numba, not a package kernel) alternated
``--reps`` times, the least CPU ms of each, and whether the two give the same sets.

::

    python experiments/chain_sets_routes.py --qvbs <QVBS> --only csma.4-2.some_before
    python experiments/chain_sets_routes.py --qvbs <QVBS> --quick

Written: ``chain_sets_routes.md`` in ``--out`` (default ``experiments/out``, a scratch
folder).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

HERE = Path(__file__).resolve().parent
QUICK = "firewire_dl.3-600.deadline"


@numba.njit(cache=False, nogil=True)
def dfs_sets(states, rows, indptr, indices, data, target, never, sure):  # pragma: no cover
    """The chain's ``never`` and ``sure`` sets by one forward depth-first search
    (Tarjan's components, iterative): a component is done after every component it
    reaches, so its sets follow from its own states and the edges leaving it (every
    state of a component reaches every other)."""
    n = target.shape[0]
    row = np.full(n, -1, dtype=np.int32)  # each acting state's row (the caller checks
    # that the rows fit an int32: fewer than the stored entries)
    for i in range(states.shape[0]):
        row[states[i]] = rows[i]
    order = np.full(n, -1, dtype=np.int32)  # the search's visit number, -1: not yet
    low = np.empty(n, dtype=np.int32)  # Tarjan's low link; -1 once its component is done
    stack = np.empty(n, dtype=np.int32)  # the states of the components not yet done
    frame = np.empty(n, dtype=np.int32)  # the search's path: its states
    at = np.empty(n, dtype=np.int32)  # and the next entry each reads
    count = top = depth = 0
    for root in range(n):
        push = root if order[root] < 0 else -1  # the state to enter next (-1: none)
        while push >= 0 or depth > 0:
            if push >= 0:  # entered: numbered, stacked, its first entry to read
                order[push] = low[push] = count
                count += 1
                stack[top] = push
                top += 1
                frame[depth] = push
                at[depth] = indptr[row[push]] if row[push] >= 0 else 0
                depth += 1
                push = -1
            v = frame[depth - 1]
            r = row[v]
            e = at[depth - 1]
            end = indptr[r + 1] if r >= 0 else 0
            went = False
            while e < end:
                if data[e] > 0.0:
                    w = indices[e]
                    if order[w] < 0:
                        at[depth - 1] = e + 1
                        push = w
                        went = True
                        break
                    if low[w] >= 0 and order[w] < low[v]:  # on the stack
                        low[v] = order[w]
                e += 1
            if went:
                continue
            depth -= 1
            if low[v] == order[v]:  # the root of a component: its states on top
                first = top - 1
                while stack[first] != v:
                    first -= 1
                reach = False  # some state a target, or an edge out to a state not never
                safe = True  # every edge out to a sure state
                for j in range(first, top):
                    u = stack[j]
                    if target[u]:
                        reach = True
                    ru = row[u]
                    if ru < 0:
                        continue
                    for f in range(indptr[ru], indptr[ru + 1]):
                        if data[f] > 0.0:
                            c = indices[f]
                            # (every head visited; on the stack: of this component,
                            # else done, its sets written)
                            if low[c] < 0:
                                if not never[c]:
                                    reach = True
                                if not sure[c]:
                                    safe = False
                for j in range(first, top):
                    u = stack[j]
                    low[u] = -1  # done
                    never[u] = not reach
                    sure[u] = reach and safe
                top = first
            if depth > 0 and low[v] >= 0:  # (not a root: its low link to its parent)
                u = frame[depth - 1]
                if low[v] < low[u]:
                    low[u] = low[v]


def _recorded(model_path: str, max_states: int) -> tuple[np.ndarray, ...]:
    """One synthesis, the certificate chain's arguments kept: ``(states, rows, indptr,
    indices, data, target)``."""
    import scipy.sparse as sp

    import mitld_lp.solvers.certify as C
    from mitld_lp import load_model, synthesize

    kept: list = []
    chain = C.chain

    def spy(mdp, target, policy, rnd, layers=None, guess=None):
        kept.append((mdp, target, policy))
        return chain(mdp, target, policy, rnd, layers, guess)

    C.chain = spy
    try:
        synthesize(load_model(model_path, max_states=max_states))
    finally:
        C.chain = chain
    mdp, target, policy = kept[-1]
    m = sp.csr_array(mdp.matrix)
    target = np.asarray(target, dtype=bool)
    policy = np.asarray(policy, dtype=np.int64)
    states = np.flatnonzero((policy >= 0) & ~target)
    return states, policy[states], m.indptr, m.indices, m.data, target


def measure(args: tuple[np.ndarray, ...], reps: int) -> dict[str, object]:
    """Both routes alternated ``reps`` times: their least CPU ms and the sets' sameness."""
    from mitld_lp.solvers.certify_kernels import chain_sets

    n = args[-1].shape[0]
    best = {"reversed": float("inf"), "dfs": float("inf")}
    got = {}
    for _ in range(reps):
        for name, kernel in (("reversed", chain_sets), ("dfs", dfs_sets)):
            never, sure = np.empty(n, dtype=bool), np.empty(n, dtype=bool)
            t = time.process_time()
            kernel(*args[:-1], args[-1].copy(), never, sure)
            best[name] = min(best[name], time.process_time() - t)
            got[name] = (never, sure)
    same = all(np.array_equal(a, b) for a, b in zip(got["reversed"], got["dfs"], strict=True))
    return {"reversed_ms": best["reversed"] * 1e3, "dfs_ms": best["dfs"] * 1e3,
            "same_sets": same, "never": int(got["reversed"][0].sum()),
            "sure": int(got["reversed"][1].sum()), "edges_rows": int(args[0].size)}


def main(argv: list[str] | None = None) -> None:
    import sys

    sys.path.insert(0, str(HERE))
    import bench_qvbs as bq

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, required=True)
    ap.add_argument("--only", nargs="*", default=[QUICK], metavar="NAME")
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--quick", action="store_true", help=f"{QUICK}, three reps")
    ap.add_argument("--out", type=Path, default=HERE / "out")
    args = ap.parse_args(argv)
    names = [QUICK] if args.quick else args.only
    reps = 3 if args.quick else args.reps
    lines = ["| instance | acting states | never | sure | reversed ms | dfs ms | same sets |",
             "|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        found, _ = bq.jobs(args.qvbs, 0, bq.MAX_STATES, bq.FAMILIES, Path(tmp))
        jobs = {inst.name: job for inst, job in found}
        for name in names:
            job = jobs[name]
            got = measure(_recorded(job["model"], job["max_states"]), reps)
            lines.append(f"| {name} | {got['edges_rows']} | {got['never']} | {got['sure']} "
                         f"| {got['reversed_ms']:.2f} | {got['dfs_ms']:.2f} "
                         f"| {got['same_sets']} |")
            print(lines[-1], flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "chain_sets_routes.md").write_text("\n".join(lines) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()

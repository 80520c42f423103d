"""The interval MDP in Storm's DRN format, with interval probabilities ``[lo, hi]``
(``stormpy.build_model_from_drn[stormpy.Interval]``; checked with
``uncertainty_resolution_mode=ROBUST``: the robot maximises, nature minimises).

A choice with ``k >= 1`` ambiguous events does not go to the product states directly:
it goes to ``2^k`` *outcome states*, one per branch ``b`` (which ambiguous events
happened), each with the interval ``[min_h w_b(h), max_h w_b(h)]`` over the hazard box
(attained at its vertices); an outcome state has one action, ``world``, whose (exact)
probabilities are the branch's row.  With one ambiguous event the two intervals
``[lo, hi]`` and ``[1 - hi, 1 - lo]`` with the sum 1 are exactly the hazards of the band,
so the file's robust value is ours.  With several, Storm's interval model lets the joint
outcome probabilities vary independently inside their intervals, a superset of the
products of per-event hazards: its robust value is then at most ours (a relaxation).

The labels a user checks are always in it: when no state satisfies the task robustly
(the value is 0), ``target`` and ``accept`` are carried by one more state after the
others, which no state reaches and which loops on itself, so that Storm knows them (its
DRN format declares labels only on states) and ``Pmax=? [F "target"]`` is 0, not an
error.

Storm 2.0 computes until probabilities on interval models only when they are *graph
preserving*: every interval written has a positive lower end.  A band reaching 0 or 1
(a Kaplan-Meier band, a fit with no event in some step) writes intervals ``[0, x]``; the
file is still the model, but Storm refuses to check it.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from mitld_lp.files import write as files
from mitld_lp.mdp import ABSORB
from mitld_lp.product.imdp import IntervalMDP, vertex_weights
from mitld_lp.solvers.export import DRN_SUFFIXES, _drn_action

__all__ = ["branch_intervals", "write_interval_drn"]

logger = logging.getLogger(__name__)


def branch_intervals(imdp: IntervalMDP) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` per branch: the least and the greatest probability of the branch over
    its choice's hazard box (``1, 1`` for the one branch of a choice without
    ambiguity)."""
    lo = np.ones(imdp.n_branches)
    hi = np.ones(imdp.n_branches)
    k = np.diff(imdp.band_groups)
    for kk in np.unique(k[k > 0]).tolist():
        cs = np.flatnonzero(k == kk)
        at = imdp.band_groups[cs][:, None] + np.arange(kk)[None, :]
        w = vertex_weights(imdp.band_lo[at], imdp.band_hi[at])  # (m, vertex, branch)
        rows = imdp.branch_groups[cs][:, None] + np.arange(1 << kk)[None, :]
        lo[rows] = w.min(axis=1)
        hi[rows] = w.max(axis=1)
    return lo, hi


def _interval(lo: float, hi: float) -> str:
    return f"[{lo!r}, {hi!r}]"


def write_interval_drn(
    imdp: IntervalMDP,
    target: np.ndarray,
    path: str | os.PathLike[str],
    *,
    overwrite: bool = False,
) -> Path:
    """Write ``imdp`` as an interval DRN (module docstring).  States ``0 .. n-1`` are the
    product's, the outcome states follow (then, when ``target`` is empty, the state
    that carries ``target`` and ``accept``).  Labels: ``init``; ``target`` and
    ``accept`` on ``target`` (for a task with a safety part, the states from which it
    is kept robustly: :func:`mitld_lp.routes.robust.interval_export`, a result's
    ``goal``); ``sink``; ``truncated``.  Raises ``FileExistsError`` (``path`` exists,
    no ``overwrite``) or ``ValueError`` (a path
    :func:`mitld_lp.files.write.writable_path` refuses)."""
    target = np.asarray(target, dtype=bool)
    p = files.writable_path(path, overwrite=overwrite, suffixes=DRN_SUFFIXES)
    n = imdp.n_states
    k = np.diff(imdp.band_groups)
    n_branch = np.diff(imdp.branch_groups)
    outcome_first = np.full(imdp.n_choices, -1, dtype=np.int64)  # first outcome state
    ambiguous = np.flatnonzero(k > 0)
    outcome_first[ambiguous] = n + np.concatenate([[0], np.cumsum(n_branch[ambiguous])[:-1]])
    n_out = int(n_branch[ambiguous].sum())
    b_lo, b_hi = branch_intervals(imdp)
    names = [_drn_action(a) for a in imdp.action_names]
    marks = [("target", target), ("accept", target), ("sink", np.asarray(imdp.sink, bool)),
             ("truncated", np.asarray(imdp.truncated, bool))]
    m = imdp.branches
    indptr = [int(x) for x in m.indptr]
    cols: list[int] = m.indices.tolist()
    vals: list[float] = m.data.tolist()
    bg, rg = imdp.branch_groups.tolist(), imdp.row_groups.tolist()
    acts = np.asarray(imdp.choice_actions, dtype=np.int64).tolist()

    def row(b: int) -> list[str]:
        return [f"\t\t{cols[j]} : {_interval(vals[j], vals[j])}"
                for j in range(indptr[b], indptr[b + 1]) if vals[j] > 0]

    unused = [] if target.any() else ["target", "accept"]
    extra = 1 if unused else 0  # the state that carries them (module docstring)
    lines = ["// Exported by mitld_lp: an interval MDP (robust synthesis)", "@type: MDP",
             "@parameters", "", "@reward_models", "", "@nr_states", str(n + n_out + extra),
             "@nr_choices", str(imdp.n_choices + n_out + extra), "@model"]
    for s in range(n):
        labels = (["init"] if s == imdp.initial else []) + [
            name for name, mask in marks if mask[s]]
        lines.append(f"state {s} {' '.join(labels)}".rstrip())
        for c in range(rg[s], rg[s + 1]):
            a = acts[c]
            lines.append(f"\taction {names[a] if a != ABSORB else 'absorb'}")
            if outcome_first[c] < 0:
                lines += row(bg[c])
                continue
            for j, b in enumerate(range(bg[c], bg[c + 1])):
                if b_hi[b] > 0:
                    lines.append(f"\t\t{int(outcome_first[c]) + j} : "
                                 f"{_interval(float(b_lo[b]), float(b_hi[b]))}")
    for c in ambiguous.tolist():
        for j, b in enumerate(range(bg[c], bg[c + 1])):
            lines.append(f"state {int(outcome_first[c]) + j}")
            lines.append("\taction world")
            lines += row(b)
    if unused:  # reached by no state: only so that Storm knows these labels
        lines += [f"state {n + n_out} {' '.join(unused)}", "\taction absorb",
                  f"\t\t{n + n_out} : {_interval(1.0, 1.0)}"]
    with files.replacing(p) as f:
        f.write("\n".join(lines) + "\n")
    logger.info("wrote interval DRN (%d states, %d outcome states) to %s", n, n_out, p)
    return p

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

import os
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from mitld_lp.files import drn
from mitld_lp.files import write as files
from mitld_lp.files.drn import DrnModel
from mitld_lp.product.imdp import IntervalMDP, vertex_weights

__all__ = ["branch_intervals", "interval_drn", "write_interval_drn"]


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


def interval_drn(imdp: IntervalMDP, target: np.ndarray) -> DrnModel:
    """What :func:`write_interval_drn` writes (module docstring): the product's states
    ``0 .. n-1``, then one outcome state per branch of each ambiguous choice, in choice
    order; the product's choices, then the outcome states' ``world``."""
    target = np.asarray(target, dtype=bool)
    n, n_c = imdp.n_states, imdp.n_choices
    bg = np.asarray(imdp.branch_groups, dtype=np.int64)
    n_branch = np.diff(bg)
    ambiguous = np.diff(imdp.band_groups) > 0
    outcome = np.flatnonzero(np.repeat(ambiguous, n_branch))  # branches: outcome states
    n_out = outcome.size
    b_lo, b_hi = branch_intervals(imdp)
    # the rows of the file's choices: a plain choice's one branch, an ambiguous one's
    # outcome states with the branches' intervals, each outcome state's branch
    m = imdp.branches
    plain = bg[:-1][~ambiguous]
    rows_of = np.concatenate([plain, outcome])  # branch rows copied, by file choice
    choice_of = np.concatenate([np.flatnonzero(~ambiguous), n_c + np.arange(n_out)])
    lengths = np.diff(m.indptr)[rows_of]
    at = np.repeat(m.indptr[rows_of] - (np.cumsum(lengths) - lengths),
                   lengths) + np.arange(int(lengths.sum()))
    owner = np.repeat(np.arange(n_c), n_branch)[outcome]  # the ambiguous choice of each
    row = np.concatenate([np.repeat(choice_of, lengths), owner])
    col = np.concatenate([m.indices[at], n + np.arange(n_out)])
    lo = np.concatenate([m.data[at], b_lo[outcome]])
    hi = np.concatenate([m.data[at], b_hi[outcome]])
    order = np.argsort(row, kind="stable")
    indptr = np.zeros(n_c + n_out + 1, dtype=np.int64)
    np.cumsum(np.bincount(row, minlength=n_c + n_out), out=indptr[1:])
    matrix = sp.csr_array((lo[order], col[order], indptr), shape=(n_c + n_out, n + n_out))
    row_groups = np.concatenate([imdp.row_groups, n_c + 1 + np.arange(n_out)])
    world = len(imdp.action_names)  # the outcome states' one action
    actions = np.concatenate([imdp.choice_actions, np.full(n_out, world)])
    pad = np.zeros(n_out, dtype=bool)
    labels = tuple((name, np.concatenate([np.asarray(mask, dtype=bool), pad])) for name, mask
                   in (("target", target), ("accept", target), ("sink", imdp.sink),
                       ("truncated", imdp.truncated)))
    return DrnModel(matrix=matrix, row_groups=row_groups, initial=int(imdp.initial),
                    labels=labels, declared=("target", "accept"),
                    action_names=(*imdp.action_names, "world"), choice_actions=actions,
                    upper=hi[order],
                    comment="Exported by mitld_lp: an interval MDP (robust synthesis)")


def write_interval_drn(
    imdp: IntervalMDP,
    target: np.ndarray,
    path: str | os.PathLike[str],
    *,
    overwrite: bool = False,
) -> Path:
    """Write ``imdp`` as an interval DRN (module docstring) through the one DRN writer
    (:mod:`mitld_lp.files.drn`).  States ``0 .. n-1`` are the
    product's, the outcome states follow (then, when ``target`` is empty, the state
    that carries ``target`` and ``accept``).  Labels: ``init``; ``target`` and
    ``accept`` on ``target`` (for a task with a safety part, the states from which it
    is kept robustly: :func:`mitld_lp.routes.robust.interval_export`, a result's
    ``goal``); ``sink``; ``truncated``.  Raises ``FileExistsError`` (``path`` exists,
    no ``overwrite``) or ``ValueError`` (a path
    :func:`mitld_lp.files.write.writable_path` refuses)."""
    p = files.writable_path(path, overwrite=overwrite, suffixes=drn.SUFFIXES)
    return drn.write(interval_drn(imdp, target), p, overwrite=overwrite)

"""The controlled model of a randomised controller synthesised with constraints (or
``then``) and a law known only within a band, as an interval model for Storm's robust
check (docs/robust.md, "Constraints").

Its states are the merged model's (:mod:`mitld_lp.solvers.constrained_model`) that the
answer solved, one *node* per choice the controller takes, and one sink per state where
it stays for ever:

* a merged state moves to the node of each choice with the controller's probability of
  it (and to its stay sink with the probability of staying);
* a node is nature's: one choice per corner of the hazard box of its choice (the vertex
  rows, :mod:`mitld_lp.solvers.robust_merged`), each the exact distribution at that
  corner, written as point intervals -- nature's best reply to any policy is at a corner,
  so these are exactly its power, as in :mod:`mitld_lp.running.band_chain` for several
  band events at once.

Labels: ``accept`` where the task is accepted (a verdict state, or a stay sink whose
state has accepted it), ``c1``, ``c2``, ... the same for each probability constraint's
formula, ``truncated``, and ``decided`` where the task is decided or the run stopped.
The reward model ``steps`` earns, in each merged state, the controller's expected steps
there (1 where the task is undecided).  Storm's ``Pmin=? [F "accept"]`` with the
uncertainty resolved to the minimum is the controller's worst case over the bands, at
least ``lower``;
``Pmax=? [F ("c1" | "truncated")]`` (uncertainty MAXIMIZE) a ``P(.) <= x``
constraint's worst case (truncation counted against it), at most its bound;
``R{"steps"}max=? [F "decided"]`` (``decided``: the task decided, or the run
stopped) the worst expected steps, at most the answer's ``steps``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.automata.joint import ACCEPTED
from mitld_lp.files import drn
from mitld_lp.files import write as files
from mitld_lp.files.drn import DrnModel, Reward

__all__ = ["is_band_mixture", "mixture_chain_drn", "mixture_claim", "write_mixture_chain",
           "MIXTURE_PROPERTY"]

MIXTURE_PROPERTY = 'Pmin=? [F "accept"]'
"""The property Storm checks on the file, with ``uncertainty_resolution_mode=MINIMIZE``."""


def is_band_mixture(result: Any) -> bool:
    """Whether ``result`` is a constrained answer with a band (its part keeps nature's
    options on its merged model)."""
    part = getattr(result, "part", None)
    return getattr(part, "options", None) is not None and bool(result.bands)


def mixture_chain_drn(result: Any) -> DrnModel:
    """The controlled interval model of the module docstring."""
    if not is_band_mixture(result):
        raise ValueError("not an answer with constraints and a band")
    part = result.part
    merged, opts, prob, stay = part.merged, part.options, part.prob, part.stay
    mdp = merged.mdp
    m, cs = mdp.n_states, mdp.choice_state()
    live = ~merged.absorbing
    used = np.flatnonzero((prob > 0) & live[cs])
    stays = np.flatnonzero((stay > 0) & live)
    n_nodes = used.size
    n = m + n_nodes + stays.size
    node = np.full(mdp.n_choices, -1, dtype=np.int64)
    node[used] = m + np.arange(n_nodes)
    sink = np.full(m, -1, dtype=np.int64)
    sink[stays] = m + n_nodes + np.arange(stays.size)
    total = np.bincount(cs, weights=prob, minlength=m) + stay
    safe = np.where(total > 0, total, 1.0)
    # the merged states' rows: one each
    share = prob[used] / safe[cs[used]]
    rows = [cs[used], stays, np.flatnonzero(merged.absorbing)]
    cols = [node[used], sink[stays], np.flatnonzero(merged.absorbing)]
    vals = [share, stay[stays] / safe[stays], np.ones(int(merged.absorbing.sum()))]
    head = sp.csr_array((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                        shape=(m, n))
    # the nodes' rows: nature's corners
    from mitld_lp.solvers.robust_graph import gather

    picked = sp.csr_array(opts.matrix[gather(opts.groups[used], opts.groups[used + 1])])
    corners = sp.csr_array((picked.data, picked.indices, picked.indptr),
                           shape=(picked.shape[0], n))
    tail = sp.csr_array((np.ones(stays.size), (np.arange(stays.size), sink[stays])),
                        shape=(stays.size, n))
    matrix = sp.csr_array(sp.vstack([head, corners, tail]))
    matrix.sort_indices()
    per_state = np.concatenate([np.ones(m, dtype=np.int64), np.diff(opts.groups)[used],
                                np.ones(stays.size, dtype=np.int64)])
    row_groups = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(per_state, out=row_groups[1:])
    labels = []
    n_prob = sum(c.constraint.kind == "prob" for c in part.constraints)
    for k, name in [(0, "accept"), *((i, f"c{i}") for i in range(1, n_prob + 1))]:
        sat = merged.verdicts[:, k] == ACCEPTED
        mask = np.zeros(n, dtype=bool)
        mask[:m] = merged.absorbing & sat & ~merged.truncated
        mask[sink[stays]] = sat[stays]
        labels.append((name, mask))
    trunc = np.zeros(n, dtype=bool)
    trunc[:m] = merged.truncated
    labels.append(("truncated", trunc))
    decided = np.ones(n, dtype=bool)
    decided[:m] = merged.absorbing | ~merged.undecided
    decided[m:m + n_nodes] = False
    labels.append(("decided", decided))
    from mitld_lp.solvers.constrained_model import Quantity, columns

    per_choice, _ = columns(merged, Quantity("steps"))
    steps = np.zeros(int(row_groups[-1]))
    steps[:m] = np.bincount(cs[used], weights=share * per_choice[used], minlength=m)
    return DrnModel(matrix=matrix, row_groups=row_groups, initial=int(mdp.initial),
                    kind="MDP", labels=tuple(labels),
                    declared=tuple(name for name, _ in labels),
                    upper=matrix.data.copy(), rewards=(Reward("steps", choice=steps),),
                    comment="The controlled interval model of a randomised controller "
                    "with constraints and a band (nature's corners as choices), exported "
                    "by mitld_lp")


def mixture_claim(result: Any) -> tuple[float, str]:
    """What Storm's check of the file gives, against ``result``'s bracket: the bound and
    the sentence the command line prints."""
    how = f"{MIXTURE_PROPERTY} with uncertainty MINIMIZE (nature's corners minimising)"
    if result.complemented:
        bound = result.complement[0] if result.complement is not None else 1 - result.upper
        return bound, (f"{how} >= the complement's lower = {bound!r}: for a minimised "
                       "task \"accept\" marks the runs that fail it")
    return result.lower, f"{how} >= lower = {result.lower!r}, the worst case over the bands"


def write_mixture_chain(result: Any, path: str | os.PathLike[str], *,
                        overwrite: bool = False) -> Path:
    """Write :func:`mixture_chain_drn` of ``result`` to ``path`` (``.drn``) under the
    package's rule for output files."""
    out = files.writable_path(path, overwrite=overwrite, suffixes=drn.SUFFIXES)
    return drn.write(mixture_chain_drn(result), out, overwrite=overwrite)

"""The merged model of a constrained synthesis in Storm's DRN format, for a check by
Storm's multi-objective engine: ``multi(Pmax=? [F "target"], P<=x [F "c1"], R{"steps"}<=y [C])``.

Labels: ``init``; ``target`` on the states where the task has accepted; ``cI`` on the
states where the ``I``-th probability constraint's formula has accepted.  One reward
model, ``steps``: 1 on every choice of a state where the task is undecided (what
``E(steps)`` counts), 0 elsewhere.  Staying in an end component for ever is a run that
never reaches a label, as in Storm's semantics.
"""

from __future__ import annotations

import os
from pathlib import Path

from mitld_lp.automata.joint import ACCEPTED
from mitld_lp.files import write as files
from mitld_lp.solvers.constrained_model import Merged

__all__ = ["write_merged_drn"]


def write_merged_drn(merged: Merged, path: str | os.PathLike[str], *,
                     overwrite: bool = False) -> Path:
    """Write ``merged`` to ``path`` (see the module docstring)."""
    mdp = merged.mdp
    k = merged.verdicts.shape[1]
    lines = ["@type: MDP", "@parameters", "", "@reward_models", "steps", "@nr_states",
             str(mdp.n_states), "@nr_choices", str(mdp.n_choices), "@model"]
    indptr, cols, vals = mdp.matrix.indptr, mdp.matrix.indices, mdp.matrix.data
    for s in range(mdp.n_states):
        labels = ["init"] if s == mdp.initial else []
        if merged.verdicts[s, 0] == ACCEPTED:
            labels.append("target")
        labels += [f"c{i}" for i in range(1, k) if merged.verdicts[s, i] == ACCEPTED]
        lines.append(" ".join([f"state {s} [0]", *labels]))
        reward = 1 if merged.undecided[s] else 0
        for j, c in enumerate(range(int(mdp.row_groups[s]), int(mdp.row_groups[s + 1]))):
            lines.append(f"\taction {j} [{reward}]")
            lines.extend(f"\t\t{int(t)} : {float(p)!r}"
                         for t, p in zip(cols[indptr[c]:indptr[c + 1]],
                                         vals[indptr[c]:indptr[c + 1]], strict=True))
    return files.write_text(path, "\n".join(lines) + "\n", overwrite=overwrite,
                            suffixes=(".drn",))

"""The merged model of a constrained synthesis in Storm's DRN format, for a check by
Storm's multi-objective engine: ``multi(Pmax=? [F "target"], P<=x [F "c1"], R{"steps"}<=y [C])``.

Labels: ``init``; ``target`` on the states where the task has accepted; ``cI`` on the
states where the ``I``-th probability constraint's formula has accepted (each declared
even when no state carries it: :mod:`mitld_lp.files.drn`).  One reward model, ``steps``:
1 on every choice of a state where the task is undecided (what ``E(steps)`` counts), 0
elsewhere.  Staying in an end component for ever is a run that never reaches a label, as
in Storm's semantics.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from mitld_lp.automata.joint import ACCEPTED
from mitld_lp.files import drn
from mitld_lp.files.drn import DrnModel, Reward
from mitld_lp.solvers.constrained_model import Merged

__all__ = ["merged_drn", "write_merged_drn"]


def merged_drn(merged: Merged) -> DrnModel:
    """What :func:`write_merged_drn` writes (module docstring)."""
    mdp = merged.mdp
    accepted = merged.verdicts == ACCEPTED
    labels = (("target", accepted[:, 0]),
              *((f"c{i}", accepted[:, i]) for i in range(1, accepted.shape[1])))
    steps = merged.undecided[mdp.choice_state()].astype(np.int64)
    return DrnModel(matrix=mdp.matrix, row_groups=mdp.row_groups, initial=int(mdp.initial),
                    labels=labels, declared=tuple(name for name, _ in labels),
                    rewards=(Reward("steps", state=np.zeros(mdp.n_states, dtype=np.int64),
                                    choice=steps),))


def write_merged_drn(merged: Merged, path: str | os.PathLike[str], *,
                     overwrite: bool = False) -> Path:
    """Write ``merged`` to ``path`` (see the module docstring)."""
    return drn.write(merged_drn(merged), path, overwrite=overwrite)

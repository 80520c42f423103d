"""The vectorised DRN writer against a line-by-line reference written here."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp import GridWorld, Model
from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.solvers import write_drn
from mitld_lp.synthesis import build_product
from mitld_lp.testing import random_mdp


def reference_drn(mdp: MDP, target: np.ndarray, valuations: bool,
                  truncated_label: bool) -> str:
    """The DRN text, one line at a time, straight from the format's description."""
    lines = ["// Exported by mitld_lp", "@type: MDP", "@parameters", "", "@reward_models", "",
             "@nr_states", str(mdp.n_states), "@nr_choices", str(mdp.n_choices), "@model"]
    dense = mdp.matrix.toarray()
    for s in range(mdp.n_states):
        labels = ["init"] if s == mdp.initial else []
        # the goal is labelled "target" and, for tasks with a safety part, "accept"
        labels += [name for name, mask in (("target", target), ("accept", target),
                                           ("sink", mdp.sink), ("truncated", mdp.truncated))
                   if mask[s] and (name != "truncated" or truncated_label)]
        lines.append(" ".join([f"state {s}", *labels]))
        if valuations:
            r = mdp.states[s]
            if hasattr(r, "pending"):
                game = str(r.game).replace(" ", "")
                pend = ",".join(sorted(r.pending))
                lines.append(f"//[game={game} & q={r.automaton} & pending={{{pend}}} & "
                             f"clock={r.clock}]")
            else:
                lines.append(f"//[{r}]" if isinstance(r, str) else
                             f"//[state={str(r).replace(' ', '')}]")
        for c in mdp.choices(s):
            a = int(mdp.choice_actions[c])
            name = "absorb" if a == ABSORB else mdp.action_names[a].replace(" ", "_")
            lines.append(f"\taction {name}")
            for t in np.flatnonzero(dense[c] > 0):
                lines.append(f"\t\t{t} : {float(dense[c, t])!r}")
    return "\n".join(lines) + "\n"


def shuffled_rows(mdp: MDP, seed: int) -> MDP:
    """``mdp`` with each row's entries stored out of order and an explicit zero added."""
    rng = np.random.default_rng(seed)
    m = sp.csr_array(mdp.matrix)
    data, indices = m.data.copy(), m.indices.copy()
    for r in range(m.shape[0]):
        lo, hi = m.indptr[r], m.indptr[r + 1]
        order = rng.permutation(hi - lo)
        data[lo:hi], indices[lo:hi] = data[lo:hi][order], indices[lo:hi][order]
    rows = np.repeat(np.arange(m.shape[0]), np.diff(m.indptr))
    extra_row = int(rng.integers(m.shape[0]))
    extra_col = int(np.setdiff1d(np.arange(m.shape[1]), indices[m.indptr[extra_row]:
                                                                 m.indptr[extra_row + 1]])[0])
    rows = np.append(rows, extra_row)
    cols = np.append(indices, extra_col)
    vals = np.append(data, 0.0)
    order = np.argsort(rows, kind="stable")
    counts = np.bincount(rows, minlength=m.shape[0])
    indptr = np.concatenate([[0], np.cumsum(counts)])
    out = sp.csr_array(m.shape)
    out.data, out.indices, out.indptr = vals[order], cols[order], indptr
    return replace(mdp, matrix=out)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("valuations", [True, False])
def test_random_mdps_match_the_reference(tmp_path: Path, seed: int, valuations: bool,
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    from mitld_lp.files import drn

    mdp = shuffled_rows(random_mdp(90, seed=seed, locality=5 if seed else None), seed)
    mdp = replace(mdp, initial=3, truncated=np.arange(mdp.n_states) % 17 == 5)
    for chunk in (drn.CHUNK_STATES, 7):
        monkeypatch.setattr(drn, "CHUNK_STATES", chunk)
        path = write_drn(mdp, mdp.target, tmp_path / f"{chunk}.drn",
                         valuations=valuations, truncated_label=seed != 1)
        assert path.read_text(encoding="utf-8") == reference_drn(
            mdp, mdp.target, valuations, truncated_label=seed != 1)


def test_product_valuations_match_the_reference(tmp_path: Path) -> None:
    world = GridWorld.make(3, 3, start=(0, 0), slip=0.1, regions={"A": [(2, 2)]})
    model = Model.from_game(world, "D[pmf(0.3, 0.3, 0.4)] e & F(e & F[0,2] A)")
    mdp = build_product(model.game, model.spec, model.distributions, epsilon=0.01).mdp
    path = write_drn(mdp, mdp.target, tmp_path / "p.drn")
    assert path.read_text(encoding="utf-8") == reference_drn(mdp, mdp.target, True, True)


def test_a_prism_worlds_states_are_named_by_their_variables_in_the_drn(tmp_path):
    """export --drn wrote a PRISM world's state as game=(...); it writes its variables by
    name, as Storm's own exporter does, and Storm still reads the file: Pmax of accept is
    the answer (0.7 by hand: the one gamble that reaches g)."""
    stormpy = pytest.importorskip("stormpy")
    from mitld_lp.cli import main

    (tmp_path / "w.prism").write_text(
        "mdp\nmodule m\n  x : [0..3] init 0;\n  b : bool init false;\n"
        "  [safe] x=0 -> (x'=1);\n  [go] x=0 -> 0.3:(x'=2)&(b'=true) + 0.7:(x'=3);\n"
        "  [wait] x>0 -> true;\nendmodule\nlabel \"h\" = x=2;\nlabel \"g\" = x=3;\n")
    (tmp_path / "w.toml").write_text('name = "w"\nspec = "F g"\n[prism]\nfile = "w.prism"\n')
    drn = tmp_path / "w.drn"
    assert main(["export", str(tmp_path / "w.toml"), "--drn", str(drn), "-q"]) == 0
    lines = drn.read_text().splitlines()
    assert "//[b=false & x=0 & q=0 & pending={} & clock=0]" in lines
    assert not any("game=" in line for line in lines)
    model = stormpy.build_model_from_drn(str(drn))
    prop = stormpy.parse_properties('Pmax=? [F "accept"]')[0]
    value = stormpy.model_checking(model, prop).get_value(model.initial_states[0])
    assert value == pytest.approx(0.7, abs=1e-9)

"""A constrained policy that keeps the task's safety part (*keep* choices of the merged
model: from then on the controller plays an end component of persistent task states for
ever) goes everywhere a controller goes: saved (format version 3) and loaded, run by the
NumPy-only runtime, exported as the controlled chain and as a decision tree.

Independent routes: the saved copy is compared with the in-process controller action by
action on the same seeds and observation sequences (driven here, not by the package's
rollout); the chain's value ``P(F accept)`` is solved in the test as a dense linear
system (numpy reachability, ``scipy.linalg.solve``) and by Storm on the DRN file, and
must equal the certified value; a version 2 file (written by removing the members new
in version 3) still loads and acts the same."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from test_composition import _GRID_FILE

from mitld_lp import Observation, runtime, synthesize
from mitld_lp.cli import main
from mitld_lp.controllers.kinds import ConstrainedController, load_controller
from mitld_lp.model import load_model
from mitld_lp.running.chain import chain_of
from mitld_lp.running.tree import tree_controller, tree_of

MODELS = Path(__file__).resolve().parent.parent / "models"

CASES = {
    # a pure safety task, a co-safe constraint that needs leaving the safe corner
    "safety": _GRID_FILE.format(extra='constraints = ["P(F[0,8] goal) >= 0.5"]', law="0.3")
    .replace('spec = "G !puddle & D[mu] b & F(b & F[0,3] goal)"', 'spec = "G !puddle"')
    .replace("[distributions]\nmu = { geometric = 0.3 }\n", ""),
    # a safety part beside an event-driven co-safe part: pending events and a clock
    "events": _GRID_FILE.format(extra='constraints = ["P(F[0,6] dock) >= 0.3"]', law="0.3"),
}


def _model_file(tmp_path: Path, case: str) -> Path:
    path = tmp_path / f"{case}.toml"
    path.write_text(CASES[case])
    return path


@pytest.fixture(scope="module", params=sorted(CASES))
def kept(request, tmp_path_factory):
    path = _model_file(tmp_path_factory.mktemp(request.param), request.param)
    model = load_model(path)
    r = synthesize(model)
    assert r.route == "constrained" and r.certified
    # the policy does keep: some keep choice has positive probability
    assert bool((r.prob[r.merged.keep] > 1e-6).any())
    return path, model, r


def _reach_value(matrix, accept: np.ndarray) -> float:
    """``P(F accept)`` from state 0 of a chain: the states that reach ``accept`` by a
    boolean fixed point on the dense matrix, then ``(I - P_uu) x = P_u,accept``."""
    p = np.asarray(matrix.todense(), dtype=np.float64)
    assert np.allclose(p.sum(axis=1), 1.0, atol=1e-12)  # a stochastic matrix
    reach = accept.copy()
    while True:
        more = reach | ((p[:, reach] > 0).any(axis=1))
        if (more == reach).all():
            break
        reach = more
    if accept[0]:
        return 1.0
    if not reach[0]:
        return 0.0
    u = np.flatnonzero(reach & ~accept)
    a = np.eye(u.size) - p[np.ix_(u, u)]
    b = p[np.ix_(u, np.flatnonzero(accept))].sum(axis=1)
    x = scipy.linalg.solve(a, b)
    return float(x[int(np.flatnonzero(u == 0)[0])])


def _observations(model, controller, seed: int, steps: int = 40):
    """One run of ``controller`` in the world, driven here: successors drawn from the
    world's own distribution, each pending event happening with probability 0.3 per
    step.  Returns the observations and the actions taken."""
    game, rng = model.game, np.random.default_rng(seed)
    s, events, pending = game.initial, frozenset(), set(controller.events)
    seen, acts = [], []
    for _ in range(steps):
        seen.append((s, events))
        a = controller.act(Observation(s, events))
        acts.append(a)
        if a is None:
            break
        events = frozenset(e for e in sorted(pending) if rng.random() < 0.3)
        pending -= events
        succ = game.successors(s, a, events)
        w = np.array([q for _, q in succ])
        s = succ[int(rng.choice(len(succ), p=w / w.sum()))][0]
    return seen, acts


def test_the_saved_controller_acts_as_the_one_in_process(kept, tmp_path) -> None:
    _, model, r = kept
    path = r.controller.save(tmp_path / "kept.npz")
    meta = json.loads(np.load(path)["meta"].tobytes())
    assert meta["version"] == 5  # 3 added the keep choices; 4 the sensed kind; 5 the
    # randomised sensed kind (sensed-randomised)
    loaded = load_controller(path)
    assert isinstance(loaded, ConstrainedController)
    robot = runtime.load(path)
    keeping = 0
    for seed in range(150):
        r.controller.reset(seed=seed)
        seen, acts = _observations(model, r.controller, seed)
        keeping += r.controller.keeping
        for other in (loaded, robot):
            other.reset(seed=seed)
            got = [other.act(Observation(s, e)) if other is loaded else other.act(s, e)
                   for s, e in seen]
            assert got == acts, seed
            assert other.keeping == r.controller.keeping
    assert keeping > 10  # the runs that drew keep, and went on playing after it


def test_the_chain_value_is_the_certified_value(kept, tmp_path) -> None:
    _, _, r = kept
    chain = chain_of(r)
    assert chain.keeping.any() and all("accept" in chain.labels[i]
                                       for i in np.flatnonzero(chain.keeping))
    assert _reach_value(chain.matrix, chain.accepting()) == pytest.approx(r.lower, abs=1e-9)
    # the chain of the controller loaded back from its file: the file carries the keeps
    loaded = load_controller(r.controller.save(tmp_path / "k.npz"))
    again = chain_of(r, loaded)
    assert _reach_value(again.matrix, again.accepting()) == pytest.approx(r.lower, abs=1e-9)


def test_the_tree_decides_as_the_controller(kept) -> None:
    _, _, r = kept
    tree = tree_of(r)
    leaves = [json.dumps(n) for n in json.loads(tree.to_json())["nodes"] if "keep" in n]
    assert leaves  # some leaf holds the keep choice with what a kept run plays
    chain = chain_of(r, tree_controller(r, tree))
    assert _reach_value(chain.matrix, chain.accepting()) == pytest.approx(r.lower, abs=1e-9)
    assert "keep" in tree.to_python() and "keep:" in tree.to_dot()


def test_export_writes_the_controller_the_chain_and_the_tree(kept, tmp_path) -> None:
    """``mitld-lp export`` on a model file with constraints and a safety part (it was
    refused); Storm checks the chain against the certified value."""
    path, _, r = kept
    out = {k: tmp_path / f"k.{k}" for k in ("npz", "drn", "json")}
    assert main(["export", str(path), "--controller", str(out["npz"]), "--chain",
                 str(out["drn"]), "--tree", str(out["json"]), "-q"]) == 0
    assert load_controller(out["npz"]).randomised
    assert any("keep" in n for n in json.loads(out["json"].read_text())["nodes"])
    pytest.importorskip("stormpy")
    from test_chain import storm_accept

    assert storm_accept(out["drn"]) == pytest.approx(r.lower, abs=1e-9)


def test_a_version_2_randomised_file_still_loads_and_acts_the_same(tmp_path) -> None:
    """A randomised controller without keep choices, written as format version 2 (no
    ``keep`` / ``kept`` members), loads and acts as the one saved by this version."""
    model = load_model(MODELS / "bus_risk.toml")
    from mitld_lp.synthesis import synthesize_constrained

    r = synthesize_constrained(model, ["P(F puddle) <= 0.05"])
    assert not r.merged.keep.any()
    path = r.controller.save(tmp_path / "v3.npz")
    with np.load(path, allow_pickle=False) as z:
        members = {k: z[k] for k in z.files if k not in ("keep", "kept")}
    old = _as_version(members, 2, tmp_path / "v2.npz")
    a, b = load_controller(path), load_controller(old)
    for seed in range(30):
        r.controller.reset(seed=seed)
        seen, acts = _observations(model, r.controller, seed)
        for c in (a, b):
            c.reset(seed=seed)
            assert [c.act(Observation(s, e)) for s, e in seen] == acts
    # a version 3 file without the new members is damaged, and said so
    bad = _as_version(members, 3, tmp_path / "bad.npz")
    with pytest.raises(runtime.ControllerFileError, match="format version 3"):
        load_controller(bad)


def _as_version(members: dict[str, np.ndarray], version: int, path: Path) -> Path:
    """A controller file of ``members`` whose meta says format ``version``."""
    meta = json.loads(members["meta"].tobytes())
    meta["version"] = version
    buffer = io.BytesIO()
    np.savez(buffer, **{**members, "meta": np.frombuffer(json.dumps(meta).encode(),
                                                         dtype=np.uint8)})
    path.write_bytes(buffer.getvalue())
    return path

"""The controlled chain (issue 32, part 1): Storm's ``P=? [F "accept"]`` on the exported
DRN equals the synthesis's ``lower`` to 1e-9, for every bundled model with a point law
and for random worlds built here: deterministic and randomised controllers, tasks with
a safety part, events with clocks (truncated laws included).

Independent route: Storm (sound value iteration, precision 1e-12) on the file; the
file's ``accept`` label for a safety part is found on the chain itself (its bottom
components), not read from the synthesis."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from mitld_lp import synthesize
from mitld_lp.controllers.kinds import load_controller
from mitld_lp.distributions import geometric, pmf, poisson
from mitld_lp.model import Model, load_model
from mitld_lp.running.chain import chain_of, write_chain
from mitld_lp.synthesis import synthesize_constrained
from mitld_lp.worlds.game import ExplicitGame

stormpy = pytest.importorskip("stormpy")

MODELS = Path(__file__).resolve().parent.parent / "models"
POINT_MODELS = ["bus_grid", "bus_grid_case2", "bus_puddle", "bus_risk", "red_light",
                "corridor", "patrol", "patrol_nogo"]


def storm_accept(path: Path) -> float:
    import stormpy.environments as env_mod

    model = stormpy.build_model_from_drn(str(path))
    assert "DTMC" in str(model.model_type)
    env = stormpy.Environment()
    solver = env.solver()
    solver.set_linear_equation_solver_type(env_mod.EquationSolverType.NATIVE)
    solver.native().method = env_mod.NativeLinearEquationSolverMethod.SOUND_VALUE_ITERATION
    solver.native().precision = stormpy.Rational("1/1000000000000")
    solver.native().relative_termination_criterion = False
    prop = stormpy.parse_properties('P=? [F "accept"]')[0]
    result = stormpy.model_checking(model, prop, environment=env)
    return float(result.get_value(model.initial_states[0]))


@pytest.mark.parametrize("name", POINT_MODELS)
def test_storm_on_the_chain_of_every_bundled_model_gives_lower(name, tmp_path) -> None:
    r = synthesize(load_model(MODELS / f"{name}.toml"))
    path = write_chain(r, tmp_path / f"{name}.drn")
    assert storm_accept(path) == pytest.approx(r.lower, abs=1e-9)
    with pytest.raises(FileExistsError):
        write_chain(r, path)


def test_the_chain_is_named_by_the_worlds_variables(tmp_path) -> None:
    text = write_chain(synthesize(load_model(MODELS / "bus_grid.toml")),
                       tmp_path / "g.drn").read_text()
    assert "//[x=0 & y=0 & q=" in text and "pending={b1,b2} & clock=0]" in text
    text = write_chain(synthesize(load_model(MODELS / "corridor.toml")),
                       tmp_path / "c.drn").read_text()
    assert "//[open=false & x=0 & q=" in text
    assert "@type: DTMC" in text and "state 0 init" in text


def test_a_band_is_refused_by_name() -> None:
    r = synthesize(load_model(MODELS / "bus_fit.toml"))
    with pytest.raises(ValueError, match="no Markov chain"):
        chain_of(r)


def test_randomised_controllers_chains(tmp_path) -> None:
    m = load_model(MODELS / "bus_risk.toml")
    for bound in (0.05, 0.2):
        r = synthesize_constrained(m, [f"P(F puddle) <= {bound}"])
        assert r.status == "optimal"
        assert storm_accept(write_chain(r, tmp_path / f"r{bound}.drn")) == pytest.approx(
            r.lower, abs=1e-9)
    # the loaded copy's tables give the same chain
    loaded = load_controller(r.controller.save(tmp_path / "r.npz"))
    again = write_chain(r, tmp_path / "loaded.drn", controller=loaded)
    assert storm_accept(again) == pytest.approx(r.lower, abs=1e-9)


# --------------------------------------------------------------------------- random worlds

SPECS = [
    "D[e] a & F(a & F[0,2] goal)",                       # an event with a clock
    "G !bad & F goal",                                    # a safety part
    "G !bad",                                             # safety alone
    "G !bad & (D[e] a & F(a & F[0,3] goal))",             # both, and a clock
    "!bad U goal",
]


def random_world(rng: np.random.Generator, n: int) -> ExplicitGame:
    states = [f"s{i}" for i in range(n)]
    transitions = {}
    for s in states:
        acts = {}
        for a in ("l", "r", "w")[: int(rng.integers(1, 4))]:
            succ = rng.choice(n, size=int(rng.integers(1, 4)), replace=False)
            w = rng.random(succ.size) + 0.05
            acts[a] = {states[int(t)]: float(x) for t, x in zip(succ, w / w.sum(), strict=True)}
        transitions[s] = acts
    labels = {s: {p for p in ("goal", "bad") if rng.random() < 0.25} for s in states[1:]}
    labels[states[0]] = set()
    return ExplicitGame(initial=states[0], transitions=transitions, labels=labels,
                        proposition_names=frozenset({"goal", "bad"}))


def laws(k: int):
    return [{"e": pmf([0.3, 0.3, 0.4])}, {"e": geometric(0.4)}, {"e": poisson(2.5)}][k % 3]


@pytest.mark.parametrize("seed", range(8))
def test_random_worlds_deterministic(seed, tmp_path) -> None:
    rng = np.random.default_rng(seed)
    checked = 0
    for k, spec in enumerate(SPECS * 3):
        world = random_world(rng, int(rng.integers(4, 9)))
        dists = laws(seed + k) if "D[e]" in spec else None
        m = Model.from_game(world, spec, distributions=dists, epsilon=0.05)
        r = synthesize(m)
        path = write_chain(r, tmp_path / f"w{k}.drn")
        assert storm_accept(path) == pytest.approx(r.lower, abs=1e-9), spec
        checked += 0 < r.lower < 1
    assert checked >= 3  # not only trivial answers


@pytest.mark.parametrize("seed", range(6))
def test_random_worlds_randomised(seed, tmp_path) -> None:
    rng = np.random.default_rng(100 + seed)
    tried = 0
    for k in itertools.count():
        if tried == 2 or k > 40:
            break
        world = random_world(rng, int(rng.integers(4, 9)))
        spec = "D[e] a & F(a & F[0,2] goal)" if k % 2 else "F goal"
        dists = laws(seed + k) if "D[e]" in spec else None
        m = Model.from_game(world, spec, distributions=dists, epsilon=0.05)
        free = synthesize_constrained(m, [])
        risk = synthesize_constrained(m, ["P(F bad) >= 0"]).constraints[0].value
        if free.status != "optimal" or not 0.05 < risk:
            continue
        r = synthesize_constrained(m, [f"P(F bad) <= {risk / 2:.6f}"])
        if r.status != "optimal":
            continue
        tried += 1
        path = write_chain(r, tmp_path / f"c{k}.drn")
        assert storm_accept(path) == pytest.approx(r.lower, abs=1e-9)
    assert tried == 2

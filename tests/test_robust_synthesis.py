"""Robust synthesis end to end: the robust product, the certified bracket, the policy and
the controller, against a brute-force max-min written here, Storm's robust value
iteration on the exported interval DRN, fixed laws of the band, and today's answer when
every band is a point."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from mitld_lp import ExplicitGame, Model, load_model, synthesize
from mitld_lp.automata.sta import make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.cli import main
from mitld_lp.distributions import from_table, geometric
from mitld_lp.product import product, robust_product
from mitld_lp.routes.robust import synthesize_robust
from mitld_lp.solvers.robust_export import write_interval_drn

MODELS = Path(__file__).resolve().parents[1] / "models"


def band(lo: float, hi: float):
    return from_table({"geometric": [lo, hi]}, "distributions.mu")


# --------------------------------------------------------------------------- a small world

STATION = 3


def corridor() -> ExplicitGame:
    """Cells 0..3, the station at 3.  ``right`` moves on with 0.8 (else stays), ``left``
    moves back, ``stay`` stays; at the station the robot cannot stay (``leave`` to 2)."""
    t: dict[int, dict[str, dict[int, float]]] = {}
    for x in range(STATION):
        t[x] = {"right": {x + 1: 0.8, x: 0.2}, "stay": {x: 1.0}}
        if x > 0:
            t[x]["left"] = {x - 1: 1.0}
    t[STATION] = {"leave": {STATION - 1: 1.0}}
    return ExplicitGame(initial=0, transitions=t, labels={STATION: {"S"}})


SPEC = "D[mu] b & F(b & F[0,2] S)"


def brute_force(lo: float, hi: float, horizon: int) -> float:
    """The best probability, within ``horizon`` steps, of being at the station at the
    bus's step or one of the two after, against a nature that picks the bus's hazard in
    ``{lo, hi}`` at every step after seeing the robot's move (the extremes suffice: the
    step's value is linear in the hazard).  Phase ``"P"``: the bus is pending; ``c``:
    it came and ``c`` steps of the window are left."""
    game = corridor()
    cells = range(STATION + 1)

    def moves(x: int):
        return [dict(d) for d in game.transitions[x].values()]

    v = {(x, ph): 0.0 for x in cells for ph in ("P", 1, 2)}
    for _ in range(horizon):
        new = {}
        for x in cells:
            best = 0.0
            for d in moves(x):  # pending: nature picks the hazard after the move is chosen
                worst = min(
                    sum(p * (h * (1.0 if y == STATION else v[(y, 2)]) + (1 - h) * v[(y, "P")])
                        for y, p in d.items())
                    for h in (lo, hi))
                best = max(best, worst)
            new[(x, "P")] = best
            for c in (1, 2):
                new[(x, c)] = max(
                    sum(p * (1.0 if y == STATION else (v[(y, c - 1)] if c > 1 else 0.0))
                        for y, p in d.items())
                    for d in moves(x))
        v = new
    return v[(0, "P")]


@pytest.mark.parametrize(("lo", "hi"), [(0.2, 0.4), (0.05, 0.6), (0.3, 0.3), (0.5, 1.0)])
def test_robust_value_is_the_brute_force_max_min(lo: float, hi: float) -> None:
    law = band(lo, hi) if lo < hi else geometric(lo)
    r = synthesize(Model.from_game(corridor(), SPEC, distributions={"mu": law}))
    expected = brute_force(lo, hi, 600)
    assert r.certified, r.failed_checks
    assert r.lower == pytest.approx(expected, abs=1e-8)
    assert r.upper == pytest.approx(expected, abs=1e-8)
    assert (r.route == "robust") == (lo < hi)


def test_a_band_reaching_zero_lets_nature_hold_the_bus() -> None:
    # hazard in [0, 0.5]: nature may keep the bus away for ever (the graph changes)
    r = synthesize(Model.from_game(corridor(), SPEC, distributions={"mu": band(0.0, 0.5)}))
    assert r.certified and r.lower == 0.0 and r.upper == pytest.approx(0.0, abs=1e-12)


def test_waiting_closed_form() -> None:
    still = ExplicitGame(initial="here", transitions={"here": {"wait": {"here": 1.0}}})
    r = synthesize(Model.from_game(still, "D[mu] b & F[0,4] b",
                                   distributions={"mu": band(0.2, 0.4)}))
    assert r.lower == pytest.approx(1 - 0.8**4, abs=1e-12)
    assert r.upper == pytest.approx(1 - 0.8**4, abs=1e-12)


# --------------------------------------------------------------------------- the bus case


def bus_with(mu1, mu2) -> Model:
    m = load_model(MODELS / "bus_grid.toml")
    return Model.from_game(m.game, m.spec, distributions={"mu1": mu1, "mu2": mu2})


def test_robust_product_without_bands_is_the_product_bit_for_bit() -> None:
    for name in ("bus_grid.toml", "red_light.toml", "corridor.toml", "patrol.toml"):
        m = load_model(MODELS / name)
        sta = make_sta(to_dta(m.spec), m.distributions, m.epsilon)
        a, b = product(m.game, sta), robust_product(m.game, sta)
        assert np.array_equal(b.branch_groups, np.arange(a.n_choices + 1))
        assert b.band_lo.size == 0
        for k in ("indptr", "indices", "data"):
            assert np.array_equal(getattr(a.matrix, k), getattr(b.branches, k)), (name, k)
        assert np.array_equal(a.row_groups, b.row_groups)


@pytest.mark.parametrize("name", ["bus_grid.toml", "red_light.toml", "corridor.toml"])
def test_point_laws_through_the_robust_route_give_todays_answer(name: str) -> None:
    m = load_model(MODELS / name)
    today = synthesize(m)
    assert today.route == "plain"
    robust = synthesize_robust(m)
    assert robust.certified, robust.failed_checks
    assert robust.lower == pytest.approx(today.lower, abs=1e-9)
    assert robust.upper == pytest.approx(today.upper, abs=1e-9)


def test_robust_lower_bound_is_at_most_every_fixed_law_of_the_band() -> None:
    r = synthesize(bus_with(band(0.7, 0.9), band(0.2, 0.4)))
    assert r.route == "robust" and r.certified
    rng = np.random.default_rng(4)
    for p1, p2 in [(0.7, 0.2), (0.9, 0.4), *rng.uniform([0.7, 0.2], [0.9, 0.4], (4, 2))]:
        fixed = synthesize(bus_with(geometric(float(p1)), geometric(float(p2))))
        assert r.lower <= fixed.lower + 1e-9
    # the optimum of one law (the centre, an end) is not the robust value
    centre = synthesize(bus_with(geometric(0.8), geometric(0.3)))
    assert r.upper < centre.lower - 1e-3


def storm_robust(path: Path) -> float:
    stormpy = pytest.importorskip("stormpy")
    model = stormpy.build_model_from_drn[stormpy.Interval](str(path))
    prop = stormpy.parse_properties('Pmax=? [F "target"]')[0]
    env = stormpy.Environment()
    env.solver().min_max().precision = stormpy.Rational("1/1000000000000")
    result = stormpy.model_checking(
        model, prop, uncertainty_resolution_mode=stormpy.UncertaintyResolutionMode.ROBUST,
        environment=env)
    return float(result.get_value(0))


def test_one_ambiguous_event_equals_storm_robust_value_iteration(tmp_path: Path) -> None:
    r = synthesize(bus_with(geometric(0.8), band(0.2, 0.4)))
    assert r.route == "robust"
    path = write_interval_drn(r.imdp, r.imdp.target, tmp_path / "bus.drn")
    assert "[0.2, 0.4]" in path.read_text()
    assert storm_robust(path) == pytest.approx(r.lower, abs=1e-8)


def test_two_ambiguous_events_storm_relaxation_is_below(tmp_path: Path) -> None:
    r = synthesize(bus_with(band(0.7, 0.9), band(0.2, 0.4)))
    path = write_interval_drn(r.imdp, r.imdp.target, tmp_path / "bus.drn")
    storm = storm_robust(path)
    # Storm's joint-outcome intervals let nature do more: its value is at most ours
    assert storm <= r.lower + 1e-9
    assert storm > r.lower - 0.05


def test_single_event_corridor_equals_storm(tmp_path: Path) -> None:
    r = synthesize(Model.from_game(corridor(), SPEC, distributions={"mu": band(0.2, 0.4)}))
    path = write_interval_drn(r.imdp, r.imdp.target, tmp_path / "c.drn")
    assert storm_robust(path) == pytest.approx(r.lower, abs=1e-8)


def test_truncated_band_brackets_every_fixed_law() -> None:
    still = ExplicitGame(initial="here", transitions={"here": {"wait": {"here": 1.0}}})
    poisson_band = from_table({"poisson": [2.0, 3.0]}, "distributions.mu")
    r = synthesize(Model.from_game(still, "D[mu] b & F[0,6] b",
                                   distributions={"mu": poisson_band}))
    assert r.route == "robust" and r.certified
    from scipy import stats

    # hazards are monotone in lam: the worst law is poisson(3) at every step
    assert r.lower == pytest.approx(stats.poisson.cdf(5, 3.0), abs=1e-9)
    for lam in (2.0, 2.5, 3.0):
        assert r.lower <= stats.poisson.cdf(5, lam) + 1e-12


def test_controller_plays_the_robust_policy() -> None:
    r = synthesize(Model.from_game(corridor(), SPEC, distributions={"mu": band(0.2, 0.4)}))
    assert r.route == "robust"
    table = r.policy_table()
    assert table and all(0 <= row["value"] <= 1 for row in table)
    from mitld_lp import Observation

    c = r.controller
    c.reset()
    assert c.act(Observation(0, frozenset())) in ("right", "stay")


def test_a_safety_part_is_kept_robustly_and_a_steps_constraint_judged_at_the_worst_law() -> None:
    """G ok & D[mu] b & F[0,4] b with mu's hazard anywhere in [0.2, 0.4]: the safety part
    always holds, and nature's worst is the lowest hazard at every step, so the robust
    optimum is P(b within 4 steps) = 1 - 0.8^4 (by hand).  An expected-steps constraint
    (refused until issue 43) is judged at the worst law: the lowest hazard at every step
    waits longest: the task is decided at b or after step 4, so the worst expected steps
    are 1 + 0.8 + 0.8^2 + 0.8^3 = 2.952 (by hand; the point route at 0.2 agrees)."""
    still = ExplicitGame(initial="here", transitions={"here": {"wait": {"here": 1.0}}},
                         labels={"here": {"ok"}})
    m = Model.from_game(still, "G ok & D[mu] b & F[0,4] b",
                        distributions={"mu": band(0.2, 0.4)})
    r = synthesize(m)
    assert r.route == "robust" and r.certified, r.failed_checks
    assert r.lower == pytest.approx(1 - 0.8**4, abs=1e-9)
    assert r.upper == pytest.approx(1 - 0.8**4, abs=1e-9)
    m = Model.from_game(still, "D[mu] b & F[0,4] b", distributions={"mu": band(0.2, 0.4)})
    worst = synthesize(Model.from_game(still, "D[mu] b & F[0,4] b",
                                       distributions={"mu": band(0.2, 0.2)}),
                       constraints=["E(steps) <= 10"]).steps
    hand = Fraction(1) + Fraction(4, 5) + Fraction(16, 25) + Fraction(64, 125)
    assert worst == pytest.approx(float(hand), abs=1e-9)
    for bound, holds in ((2.9, False), (3.0, True)):
        r = synthesize(m, constraints=[f"E(steps) <= {bound}"])
        lo, hi = r.constraints[0].bounds
        assert Fraction(lo) <= hand <= Fraction(hi)
        assert r.constraints[0].holds == holds == r.certified


# --------------------------------------------------------------------------- command line


def test_cli_solve_export_and_bad_data(tmp_path: Path, capsys) -> None:
    assert main(["solve", str(MODELS / "bus_fit.toml"), "--json", "-q"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["robust"] and out["certified"] and out["lower"] <= out["upper"] + 1e-9
    assert out["bands"]["b2"] == "fit(geometric, data/bus2_arrivals.csv, 0.95)"
    drn = tmp_path / "bus.drn"
    assert main(["export", str(MODELS / "bus_fit.toml"), "--drn", str(drn), "-q"]) == 0
    assert drn.read_text().startswith("// Exported by mitld_lp: an interval MDP")
    assert main(["export", str(MODELS / "bus_fit.toml"), "--lp", str(tmp_path / "a.lp"),
                 "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no single LP" in err[0]
    # a data file with a negative time: one line naming the file and line, exit 2
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "bus2_arrivals.csv").write_text("time,censored\n3,0\n-1,0\n")
    model = tmp_path / "m.toml"
    model.write_text((MODELS / "bus_fit.toml").read_text())
    assert main(["solve", str(model), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "distributions.mu2" in err[0] and "bus2_arrivals.csv:3: time must be >= 0" in err[0]


@pytest.mark.parametrize("n_copies", [1, 5])
def test_the_answer_says_how_wide_the_data_leave_the_band(tmp_path: Path, capsys,
                                                          n_copies: int) -> None:
    """Few observations give a confident-looking fit only if nobody says how wide its band
    is: the summary carries the first step's hazard interval, which for a geometric fit is
    the exact binomial (Clopper-Pearson) interval of events in steps watched (scipy's
    ``binomtest`` here), for 12 observations and for 60."""
    from scipy import stats

    rows = [(3, 0), (1, 0), (4, 1), (2, 0), (2, 0), (5, 1), (1, 0), (3, 0), (6, 1),
            (2, 0), (4, 0), (4, 0)] * n_copies
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "bus2_arrivals.csv").write_text(
        "time,censored\n" + "".join(f"{t},{c}\n" for t, c in rows))
    model = tmp_path / "m.toml"
    model.write_text((MODELS / "bus_fit.toml").read_text())
    assert main(["solve", str(model), "--json", "-q"]) == 0
    out = json.loads(capsys.readouterr().out)
    events = sum(1 for _, c in rows if not c)
    exposure = sum(t for t, _ in rows)
    ci = stats.binomtest(events, exposure).proportion_ci(0.95, method="exact")
    lo, hi = out["first_step_hazards"]["b2"]
    assert lo == pytest.approx(ci.low, abs=1e-9) and hi == pytest.approx(ci.high, abs=1e-9)
    assert out["first_step_hazards"]["b1"] == [0.7, 0.9]
    assert main(["solve", str(model), "-q"]) == 0
    text = capsys.readouterr().out
    assert f"hazard at step 1 in [{lo:.7f}, {hi:.7f}]" in text

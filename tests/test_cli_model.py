"""The model-consuming verbs of ``mitld-lp``, and the product checked by Storm."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from mitld_lp.automata.sta import make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.cli import main
from mitld_lp.model import load_model
from mitld_lp.product import ProductState
from mitld_lp.synthesis import synthesize
from mitld_lp.testing import reference_product

MODELS = Path(__file__).resolve().parent.parent / "models"
BUS = str(MODELS / "bus_grid.toml")
RED = str(MODELS / "red_light.toml")

REQUIRED_JSON = {"lower", "upper", "value", "certified", "states", "transitions",
                 "epsilon_achieved", "method", "seconds"}


def _json(capsys) -> dict:
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("method", ["lp", "vi"])
def test_solve_json_has_the_contract_keys(capsys, method):
    assert main(["solve", BUS, "--json", "--method", method]) == 0
    out = _json(capsys)
    assert REQUIRED_JSON <= set(out)
    assert out["certified"] is True
    assert out["method"] == method
    assert out["lower"] == pytest.approx(0.9244053, abs=1e-6)
    assert out["upper"] == pytest.approx(0.9244053, abs=1e-6)


def test_solve_with_truncation_reports_a_bracket(capsys):
    assert main(["solve", RED, "--json", "--epsilon", "0.05"]) == 0
    out = _json(capsys)
    assert out["lower"] <= out["upper"]
    assert out["upper"] - out["lower"] <= out["epsilon_achieved"] + 1e-7
    assert 0 < out["epsilon_achieved"] <= 0.05


def test_solve_human_output(capsys):
    assert main(["solve", BUS]) == 0
    text = capsys.readouterr().out
    assert "certified:    yes" in text and "0.9244053" in text


def test_an_unknown_solver_is_refused_before_any_work(capsys):
    assert main(["solve", BUS, "--solver", "NO_SUCH_SOLVER", "--json"]) == 2
    captured = capsys.readouterr()
    # no answer (no JSON with NaN in it, no work done): the error object alone
    assert json.loads(captured.out)["status"] == "usage_error"
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "unknown or not installed LP solver 'NO_SUCH_SOLVER'" in err[0]
    assert "CLARABEL" in err[0]  # the installed ones are named


def test_solver_names_are_taken_in_any_case(capsys):
    assert main(["solve", BUS, "--json", "--solver", "highs", "-q"]) == 0
    out = _json(capsys)
    assert out["lp"]["solver"] == "HIGHS"
    assert out["lower"] == pytest.approx(0.9244053, abs=1e-6)


def test_a_budget_stop_exits_3_with_one_line(capsys):
    assert main(["solve", BUS, "--max-states", "10", "-q"]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("mitld-lp: stopped:") and "10" in err[0]


def test_info_counts(capsys):
    assert main(["info", BUS, "--json"]) == 0
    out = _json(capsys)
    # every count from the state-at-a-time reference construction, counted here
    m = load_model(BUS)
    ref = reference_product(m.game, make_sta(to_dta(m.spec), m.distributions, m.epsilon))
    ordinary = [s for s in ref.states if isinstance(s, ProductState)]
    expected = {
        "states": ref.n_states, "choices": ref.n_choices, "transitions": ref.n_transitions,
        "ordinary_states": len(ordinary), "target_states": int(ref.target.sum()),
        "sink_states": int(ref.sink.sum()), "truncated_states": int(ref.truncated.sum()),
        "game_states": len({s.game for s in ordinary}),
        "automaton_states": len({s.automaton for s in ordinary}),
        "event_situations": len({s.pending for s in ordinary}),
        "clock_values": len({s.clock for s in ordinary}),
    }
    assert {k: out[k] for k in expected} == expected
    # by hand: geometric events need no clock; the robot can reach each of the 16 cells;
    # any of the four sets of the two buses can still be pending; nothing is truncated
    assert (out["clock_values"], out["game_states"], out["event_situations"]) == (1, 16, 4)
    assert out["truncated_states"] == 0 and out["truncation_points"] == {}
    assert out["epsilon_achieved"] == 0


def test_info_without_clock_reduction_grows_with_the_truncation_point(capsys):
    sizes = []
    for eps in ("0.2", "0.05", "0.01"):
        assert main(["info", BUS, "--json", "--no-clock-reduction", "--epsilon", eps]) == 0
        out = _json(capsys)
        assert set(out["truncation_points"]) == {"b1", "b2"}
        sizes.append((max(out["truncation_points"].values()), out["states"]))
    assert sizes == sorted(sizes) and sizes[0][1] < sizes[-1][1]


@pytest.mark.parametrize(
    "argv",
    [
        ["solve", "no/such/model.toml"],
        ["info", str(MODELS)],  # a directory
        ["dta", "G F p"],
        ["dta", "F[3,1] p"],
        ["export", BUS],
        ["simulate", BUS, "-n", "0"],
    ],
)
def test_bad_input_exits_2_with_one_line(capsys, argv):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("mitld-lp: error:")


def test_bad_model_file_names_the_key(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(Path(BUS).read_text().replace("slip = 0.1", "slip = 0.7"))
    assert main(["solve", str(bad)]) == 2
    assert "grid.slip" in capsys.readouterr().err


def test_export_never_overwrites(tmp_path, capsys):
    out = tmp_path / "m.drn"
    out.write_text("precious")
    assert main(["export", BUS, "--drn", str(out)]) == 2
    assert out.read_text() == "precious"
    assert main(["export", BUS, "--drn", str(out), "--force"]) == 0
    assert out.read_text().startswith("// ") or "@type: MDP" in out.read_text()


def test_dta_dot(tmp_path, capsys):
    dot = tmp_path / "a.dot"
    assert main(["dta", "F(b & F[0,3] A)", "--dot", str(dot)]) == 0
    text = dot.read_text()
    assert text.startswith("digraph") and text.count("{") == text.count("}")


def test_simulate_is_consistent(capsys):
    assert main(["simulate", BUS, "-n", "1500", "--seed", "2", "--json",
                 "--max-steps", "60"]) == 0
    out = _json(capsys)
    assert out["consistent"] is True


def test_storm_checks_the_exported_product(tmp_path):
    """Storm model-checks our product (DRN) and must agree state by state with the LP's
    dual values and the interval-iteration bracket."""
    stormpy = pytest.importorskip("stormpy")
    from mitld_lp.solvers.export import write_drn
    from mitld_lp.solvers.lp import solve_lp

    for path in (BUS, RED):
        r = synthesize(load_model(path))
        for sol, target in ((r.lower_model, r.mdp.target),
                            (r.upper_model, r.mdp.target | r.mdp.truncated)):
            drn = tmp_path / f"{Path(path).stem}-{sol.which}.drn"
            write_drn(r.mdp, target, drn, overwrite=True)
            model = stormpy.build_model_from_drn(str(drn))
            assert model.nr_states == r.mdp.n_states
            prop = stormpy.parse_properties('Pmax=? [F "target"]')[0]
            # Storm's default engine stops at a relative change of 1e-6 (stormpy 2.0 does
            # not expose its solver environment), hence the tolerance below.
            result = stormpy.model_checking(model, prop)
            storm = np.array(result.get_value_vector())
            # With the initial-state objective the duals of states the optimal policy
            # never visits are only upper bounds; started from every state, the LP's
            # duals are the value function everywhere.
            lp = solve_lp(r.mdp, target, everywhere=True)
            assert lp.values is not None
            # DRN keeps our state numbering (state i of the file is state i of ours).
            np.testing.assert_allclose(lp.values, storm, atol=1e-5)
            assert sol.lp is not None and sol.lp.values is not None
            assert np.all(sol.lp.values >= storm - 1e-5)
            assert sol.lp.value == pytest.approx(storm[r.mdp.initial], abs=1e-5)
            assert np.all(sol.iteration.lower <= storm + 1e-5)
            assert np.all(storm <= sol.iteration.upper + 1e-5)


def test_small_probabilities_keep_their_significant_digits(tmp_path, capsys):
    """Two steps that each succeed with probability 1.7e-4: the value is 1.7e-4**2 =
    2.89e-8, which a fixed 7-decimal format would print as 0.0000000."""
    (tmp_path / "chain.prism").write_text(
        "mdp\nmodule chain\n  x : [0..3] init 0;\n"
        "  [go] x < 2 -> 0.00017 : (x'=x+1) + 0.99983 : (x'=3);\n"
        "  [stay] x >= 2 -> true;\nendmodule\nlabel \"goal\" = x = 2;\n")
    toml = tmp_path / "chain.toml"
    toml.write_text('name = "chain"\nspec = "F[0,3] goal"\nepsilon = 0.01\n'
                    '[prism]\nfile = "chain.prism"\nevents = []\n')
    assert main(["solve", str(toml), "-q"]) == 0
    text = capsys.readouterr().out
    line = next(x for x in text.splitlines() if x.startswith("optimum in:"))
    lower, upper = (float(v) for v in line.split("[")[1].split("]")[0].split(","))
    # printed outward to 7 significant digits: the exact 0.00017^2 inside, one unit apart
    exact = Fraction(17, 10**5) ** 2
    assert Fraction(str(lower)) <= exact <= Fraction(str(upper))
    assert Fraction(str(upper)) - Fraction(str(lower)) <= exact / 10**6
    assert "0.0000000" not in text
    assert main(["solve", str(toml), str(toml), "-q"]) == 0
    batch = capsys.readouterr().out
    assert "[2.889999e-08, 2.890001e-08]" in batch and "0.0000000" not in batch


@pytest.mark.parametrize("bad", [-1, float("nan"), float("inf"), "5"])
def test_synthesize_refuses_a_bad_time_limit(bad):
    with pytest.raises(ValueError, match="time_limit"):
        synthesize(load_model(BUS), time_limit=bad)


def test_stage_line_and_summary_count_the_same_automaton(capsys) -> None:
    """The product's stage line counts the automaton states a product state can be in
    (accepting and rejecting ones collapse into the absorbing target and sink); the
    summary counts them all. Both are read off the same automaton, built here."""
    import logging
    import re

    path = Path(__file__).resolve().parents[1] / "models" / "bus_grid.toml"
    logging.getLogger("mitld_lp").handlers.clear()
    assert main(["solve", str(path)]) == 0
    out, err = capsys.readouterr()
    stage = int(re.search(r"x (\d+) non-absorbing automaton states x", err).group(1))
    total = int(re.search(r"sizes: +(\d+) automaton states", out).group(1))
    dta = to_dta(load_model(path).spec)
    absorbing = (dta.accepting is not None) + (dta.rejecting is not None)
    assert total == dta.n_states and stage == dta.n_states - absorbing


def test_a_commands_stage_lines_are_its_own(capsys) -> None:
    """Lines logged by another thread meanwhile (an abandoned command's, in a program
    that runs several) are not this command's: they stay off its stderr."""
    import logging
    import threading

    stop = threading.Event()

    def chatter() -> None:
        while not stop.is_set():
            logging.getLogger("mitld_lp.elsewhere").info("stray line")
            stop.wait(0.001)

    other = threading.Thread(target=chatter)
    other.start()
    try:
        assert main(["solve", BUS]) == 0
    finally:
        stop.set()
        other.join()
    err = capsys.readouterr().err
    assert "stray line" not in err and "mitld-lp: product:" in err


# --------------------------------------------------------------------------- budgets


@pytest.mark.parametrize(("model", "key", "value", "flag"), [
    ("bus_grid", "max_states", "10", "10"),
    ("bus_grid", "max_automaton_states", "2", "2"),
    ("bus_grid", "max_memory", '"100K"', "100K"),
    ("corridor", "max_world_states", "3", "3"),
])
@pytest.mark.parametrize("verb", [["info"], ["solve"], ["simulate", "-n", "5"]])
def test_each_budget_of_a_model_file_binds_as_its_flag(tmp_path, capsys, model, key, value,
                                                       flag, verb):
    # issue 41: every budget in a model file is as binding as the same flag (the time
    # limit's own tests are in test_time_limit_process.py)
    if model == "corridor":
        pytest.importorskip("stormpy")
    text = (MODELS / f"{model}.toml").read_text().replace('"corridor.prism"',
                                                          f'"{MODELS / "corridor.prism"}"')
    (tmp_path / "file.toml").write_text(f"{text}\n[budgets]\n{key} = {value}\n")
    (tmp_path / "flag.toml").write_text(text)
    outcomes = []
    for name, extra in (("file", []), ("flag", [f"--{key.replace('_', '-')}", flag])):
        code = main([verb[0], str(tmp_path / f"{name}.toml"), *verb[1:], *extra, "-q"])
        err = capsys.readouterr().err.replace(str(tmp_path / f"{name}.toml"), "M")
        outcomes.append((code, err))
    assert outcomes[0] == outcomes[1]
    assert outcomes[0][0] == 3 and "stopped: " in outcomes[0][1]  # the budget did stop it

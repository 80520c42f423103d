"""One binding of a task to a world (``mitld_lp.worlds.task``): every route says the same thing.

The routes are the model file, ``Model.from_game`` and ``product`` on a hand-made STA;
each fault below is written once and must be refused by all three with one message.
"""

from __future__ import annotations

import pytest

from mitld_lp import GridWorld, Model, ModelError, loads_model, make_sta, parse, to_dta
from mitld_lp.distributions import geometric
from mitld_lp.logic.fragment import check
from mitld_lp.product import product
from mitld_lp.worlds.task import BindError, bind, check_alphabet, resolve_laws

WORLD = GridWorld.make(3, 1, start=(0, 0), regions={"A": [(2, 0)]})
GRID_TOML = """
name = "t"
spec = "{spec}"
[grid]
size = [3, 1]
start = [0, 0]
[regions]
A = [[2, 0]]
"""


def _routes(spec: str, reason: str, path: str) -> None:
    """The file loader, ``Model.from_game`` and ``product`` refuse ``spec`` on WORLD with
    ``reason`` (the file at key path ``path``; the library, which declares no tables,
    at ``spec``)."""
    with pytest.raises(ModelError) as file_err:
        loads_model(GRID_TOML.format(spec=spec), "m.toml")
    assert str(file_err.value) == f"m.toml: {path}: {reason}"
    lib_reason = reason.replace("region", "proposition")
    with pytest.raises(ModelError) as lib_err:
        Model.from_game(WORLD, spec)
    lib_path = path if path.startswith("distributions") else "spec"
    assert str(lib_err.value) == f"<spec>: {lib_path}: {lib_reason}"
    formula = parse(spec)
    laws = {e: geometric(0.5) for e, _ in check(formula).events}
    with pytest.raises(BindError) as prod_err:
        product(WORLD, make_sta(to_dta(formula), laws, 0.01))
    assert str(prod_err.value) == lib_reason


def test_a_proposition_that_is_neither_region_nor_event_is_refused_on_every_route():
    _routes(
        "F[0,5] B",
        "proposition 'B' is neither a region nor an event (regions: A; events: none)",
        "spec",
    )


def test_an_event_with_a_region_name_is_refused_on_every_route():
    # Before, product() accepted it: the letter then carried A both as the region and
    # as the event, and the answer mixed the two.
    _routes(
        "D[geometric(0.5)] A & F[0,3] A",
        "region 'A' has the name of an event of spec (an event is not a region)",
        "regions.A",
    )


def test_resolve_laws_looks_names_up_builds_literals_and_refuses_unused_names():
    report = check(parse("D[mu] b & D[geometric(0.25)] c & F(b & c)"))
    laws = resolve_laws(report, {"mu": geometric(0.5)})
    assert laws.keys() == {"b", "c"}
    assert laws["b"].hazard(1) == pytest.approx(0.5)
    assert laws["c"].hazard(7) == pytest.approx(0.25)  # memoryless: the same every step
    with pytest.raises(BindError, match=r"defined but not used") as err:
        resolve_laws(report, {"mu": geometric(0.5), "nu": geometric(0.5)})
    assert err.value.key == ("distributions", "nu")
    with pytest.raises(BindError, match=r"'mu' \(of event 'b'\) is not defined"):
        resolve_laws(report, {})
    with pytest.raises(BindError, match=r"must be a distribution"):
        resolve_laws(report, {"mu": 0.5})


def test_bind_returns_the_laws_of_exactly_the_events_read_only():
    task = bind(WORLD, check(parse("D[geometric(0.5)] b & F(b & F[0,2] A)")))
    assert task.events == {"b"} and task.formula == parse("D[geometric(0.5)] b & F(b & F[0,2] A)")
    with pytest.raises(TypeError):
        task.laws["c"] = geometric(0.5)  # type: ignore[index]


def test_check_alphabet_names_the_first_fault_in_name_order():
    with pytest.raises(BindError, match=r"proposition 'B' is neither"):
        check_alphabet(WORLD, {"C", "B", "A"}, set())
    check_alphabet(WORLD, {"A", "b"}, {"b"})  # an event read by the spec is fine

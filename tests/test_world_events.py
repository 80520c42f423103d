"""Events declared by the world (``[events]``, ``Model.from_game(events=...)``): a law
without the spec asking that the event happen; the spec reads it as a proposition."""

from __future__ import annotations

import re

import pytest

from mitld_lp import GridWorld, Model, ModelError, loads_model, synthesize
from mitld_lp.cli import main
from mitld_lp.distributions import from_table

_WORLD = GridWorld.make(3, 1, start=(0, 0), regions={"A": [(2, 0)]})
_BASE = ('name = "x"\nspec = "G (door -> A)"\n{top}[grid]\nsize = [3, 1]\nstart = [0, 0]\n'
         '[regions]\nA = [[2, 0]]\n')


def test_world_event_need_not_happen() -> None:
    """The door opens at step 1 (0.3), at step 2 (0.2) or never (0.5).  The robot is on A
    from step 2 on at the earliest, so only an opening at step 1 violates ``G (door ->
    A)``: 1 - 0.3.  Asking the event with ``D[mu] door`` also demands that it happen:
    only the opening at step 2 counts, 0.2."""
    law = from_table({"pmf": [0.3, 0.2]}, "door")
    r = synthesize(Model.from_game(_WORLD, "G (door -> A)", events={"door": law}))
    assert r.certified and r.lower == pytest.approx(0.7, abs=1e-12)
    assert r.upper == pytest.approx(0.7, abs=1e-12)
    r = synthesize(Model.from_game(_WORLD, "D[pmf(0.3, 0.2)] door & G (door -> A)"))
    assert r.certified and r.lower == pytest.approx(0.2, abs=1e-12)
    from_file = loads_model(_BASE.format(top="") + "[events]\ndoor = { pmf = [0.3, 0.2] }\n")
    assert synthesize(from_file).lower == pytest.approx(0.7, abs=1e-12)


def test_truncated_world_event_keeps_a_sound_bracket() -> None:
    """A Poisson event is truncated: the bracket still holds the value, which by hand is
    1 - P(K = 1) = 1 - e^-2 (robot on A from step 2; K = 1 + Poisson(2))."""
    import math

    law = from_table({"poisson": 2}, "door")
    r = synthesize(Model.from_game(_WORLD, "G (door -> A)", events={"door": law},
                                   epsilon=1e-4))
    want = 1 - math.exp(-2)
    assert r.certified and r.lower - 1e-9 <= want <= r.upper + 1e-9
    assert r.upper - r.lower <= 1e-4 + 1e-9


@pytest.mark.parametrize(("top", "extra", "message"), [
    ("", "[events]\ndoor = 3\n", "events.door: must be an inline table"),
    ("", "[events]\ndoor = { pmf = [0.3, 0.9] }\n", "events.door.pmf: masses sum to 1.2"),
    ("", "[events]\nA = { geometric = 0.5 }\ndoor = { geometric = 0.5 }\n",
     "events.A: event 'A' has the name of a region"),
    ("events = 3\n", "", "events: must be a table"),
    ("", '[events]\n"do or" = { geometric = 0.5 }\n', "events.\"do or\": 'do or' is not a name"),
])
def test_bad_events_tables_name_the_key(top: str, extra: str, message: str, tmp_path,
                                        capsys) -> None:
    text = _BASE.format(top=top) + extra
    with pytest.raises(ModelError, match="^<string>: " + re.escape(message)):
        loads_model(text)
    path = tmp_path / "m.toml"
    path.write_text(text)
    assert main(["solve", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err


def test_from_game_events_errors() -> None:
    law = from_table({"geometric": 0.5}, "door")
    with pytest.raises(ModelError, match="events.door: event 'door' also gets a law"):
        Model.from_game(_WORLD, "D[geometric(0.5)] door & G (door -> A)", events={"door": law})
    with pytest.raises(ModelError, match="events.door: must be a distribution"):
        Model.from_game(_WORLD, "G (door -> A)", events={"door": 0.5})  # type: ignore[dict-item]
    with pytest.raises(ModelError, match="proposition 'door' is neither"):
        Model.from_game(_WORLD, "G (door -> A)")

"""The sensed route against Storm's POMDP engine (stormpy, skipped without it): the
station example of tests/test_sensing.py written here as a PRISM POMDP (the world, the
event with its per-step probabilities, the sensor, what the robot observes: its cell,
the step count and whether the sensor has reported), and Storm's belief unfolding's
``Pmax=? [F "win"]`` when its exploration completes, which is then the optimum over
observation-based policies."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_sensing import PMF, SPEC, STATION, WINDOW

from mitld_lp import Model, synthesize

pomdp = pytest.importorskip("stormpy.pomdp")
stormpy = pytest.importorskip("stormpy")

ACTIONS = {"go": "s=0", "wait": "s=0", "swait": "s=1", "back": "s=1", "stay": "s=2"}


def station_prism(detect: float) -> str:
    """tests/test_sensing.py's STATION (mid = 0, st = 1, ditch = 2; the station's
    ``wait`` is ``swait`` here) with the bus at step k ~ PMF and a sensor."""
    n, survival = len(PMF), [1.0]
    for p in PMF:
        survival.append(survival[-1] - p)
    hazard = [PMF[k] / survival[k] for k in range(n)]  # the event at step k + 1
    top_t, top_a = n + WINDOW + 1, WINDOW + 1
    tick, age = f"(t'=min(t+1,{top_t}))", f"(a'=min(a+1,{top_a}))"
    lines = ["pomdp", "observables s, t, rep endobservables", "module robot",
             "  s : [0..2] init 0;",
             "  [go] s=0 -> 0.8:(s'=1) + 0.2:(s'=2);", "  [wait] s=0 -> 1:(s'=0);",
             "  [swait] s=1 -> 0.5:(s'=1) + 0.5:(s'=2);",
             "  [back] s=1 -> 0.8:(s'=0) + 0.2:(s'=2);", "  [stay] s=2 -> 1:(s'=2);",
             "endmodule", "module bus", f"  t : [0..{top_t}] init 0;",
             "  e : [0..1] init 0;", f"  a : [0..{top_a}] init 0;", "  rep : [0..1] init 0;"]
    for act in ACTIONS:
        for k, h in enumerate(hazard):
            parts = []
            if h > 0 and detect > 0:
                parts.append(f"{h * detect}:(e'=1)&(a'=0)&(rep'=1)&{tick}")
            if h > 0 and detect < 1:
                parts.append(f"{h * (1 - detect)}:(e'=1)&(a'=0)&{tick}")
            if h < 1:
                parts.append(f"{1 - h}:{tick}")
            lines.append(f"  [{act}] e=0 & t={k} -> {' + '.join(parts)};")
        seen = [f"{detect}:(rep'=1)&{age}&{tick}"] if detect > 0 else []
        seen += [f"{1 - detect}:{age}&{tick}"] if detect < 1 else []
        lines.append(f"  [{act}] e=1 & rep=0 -> {' + '.join(seen)};")
        lines.append(f"  [{act}] e=1 & rep=1 -> 1:{age}&{tick};")
    lines += ["endmodule", f'label "win" = s=1 & e=1 & a<={WINDOW};']
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("detect", [0.0, 0.5, 0.8])
def test_storm_belief_unfolding_agrees(tmp_path: Path, detect: float) -> None:
    assert set(STATION.actions("mid")) == {"go", "wait"}  # the PRISM text's world
    path = tmp_path / "station.prism"
    path.write_text(station_prism(detect))
    program = stormpy.parse_prism_program(str(path))
    prop = stormpy.parse_properties('Pmax=? [F "win"]', program)[0]
    storm = pomdp.verify_with_belief_unfolding(stormpy.build_model(program, [prop]), prop)
    assert storm.completed_exploration
    ours = synthesize(Model.from_game(STATION, SPEC, sensors={"b": {"detect": detect}}))
    assert ours.lower - 1e-7 <= storm.value <= ours.upper + 1e-7

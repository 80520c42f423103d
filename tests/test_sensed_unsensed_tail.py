"""A camera on one event and, beside it, an unsensed event (seen the step it happens)
whose band has no truncation point (issue 43): its hazard may stay positive for ever
while its laws' never masses differ.  The sensed build once raised ``UnboundedBand``
there; now that event's clock runs to the band's step ``K`` and keeps the outer
constant interval (the inner one for the best law), as a sensed event's does
(tests/test_sensed_never_tail.py).

The world of tests/test_false_alarms_never_band.py (wait at ``mid`` or go to ``A``,
reached the next step and left for good); the task asks the robot at ``A`` one step
after the bus ``b`` or the cab ``c`` comes, at a step ``k <= 3``.  The bus has the point
law ``pmf [0.3, 0.3]`` (hazards 3/10 and 3/7, then 0) and a camera that reports it with
probability 7/10 at each step from its coming until it has reported it once; the cab's
band is tests/test_sensed_never_tail.py's ``POISSON`` (the middle law ``pmf [0.3, 0.3]``
beside ``pmf [0.2, 0.3]`` and a Poisson law).  An event at step 4 or later, or never,
serves no part of the task, so the enumeration below over steps 1..3 is exact whatever
the tail: nothing past the horizon is left to bound.

Independent routes: an enumeration in fractions over both events' steps, nature's cab
hazard at each step at an end of the true interval (a step's value is linear in it)
and the camera's reports, with the returned controller replayed; every deterministic
observation-based controller that goes when it sees the cab (which then surely wins:
no controller does better there) by brute force over the 2^5 tables of the rest;
Storm's robust check of the exported interval chain."""

from __future__ import annotations

import importlib.util
import itertools
from fractions import Fraction
from pathlib import Path
from typing import Any

import pytest
from test_false_alarms_never_band import GAME
from test_sensed_never_tail import poisson_band, poisson_hazards

from mitld_lp import Model, synthesize
from mitld_lp.distributions import pmf
from mitld_lp.sensing import Sensor

SPEC = "D[mu] b & D[nu] c & F[0,3] ((b | c) & F[1,1] A)"
DETECT = Fraction(7, 10)
BUS = {1: Fraction(3, 10), 2: Fraction(3, 7)}  # pmf [0.3, 0.3]'s hazards; 0 after
LAST = 3
CAB = poisson_hazards(2.0)
TOL = Fraction(1, 10**9)


def model() -> Model:
    return Model.from_game(GAME, SPEC, distributions={"mu": pmf([0.3, 0.3]),
                                                      "nu": poisson_band()},
                           sensors={"b": Sensor(float(DETECT))})


def value(act: Any, pick: Any) -> Fraction:
    """The task's probability under ``act`` (observation history -> action; a history
    is ``(state, cab seen, bus reported)`` per step) with nature choosing the cab's
    hazard at each step at an end of its interval by ``pick`` (``min``: the worst case,
    ``max``: the best), seeing everything.  ``D[mu] b & D[nu] c`` read as ``F b & F c``
    (docs/semantics.md): both must come.  The bus has come by step 2 or never; a cab
    still pending after step 4 comes later with probability 0 in the worst case (the
    tables' hazard, the interval's low end, is 0 from step 3 on) and 1 in the best
    (nature may play the Poisson law's hazards, whose survival falls to 0)."""
    later = Fraction(0) if pick is min else Fraction(1)

    def go(t: int, state: str, kb: int | None, told: bool, kc: int | None, won: bool,
           seen: tuple[Any, ...]) -> Fraction:
        if t > LAST:  # the task's F part decided; the bus's law is over
            if not won or kb is None:
                return Fraction(0)
            return Fraction(1) if kc is not None else later
        action = act(seen) if state == "mid" else "back"
        bus = [(kb, Fraction(1))] if kb is not None else [
            (t + 1, BUS.get(t + 1, Fraction(0))), (None, 1 - BUS.get(t + 1, Fraction(0)))]
        cabs = [[(kc, Fraction(1))]] if kc is not None else [
            [(t + 1, h), (None, 1 - h)] for h in CAB(t + 1)]
        values = []
        for cab in cabs:
            v = Fraction(0)
            for (kb2, pb), (kc2, pc) in itertools.product(bus, cab):
                if pb * pc == 0:
                    continue
                d = DETECT if kb2 is not None and not told else Fraction(0)
                for rep, pr in ((True, d), (False, 1 - d)):
                    if pr == 0:
                        continue
                    for nxt, pw in GAME.successors(state, action, frozenset()):
                        # at A one step after an event at step t >= 1
                        now = won or (nxt == "sa" and t >= 1 and t in (kb, kc))
                        v += pb * pc * pr * Fraction(str(pw)) * go(
                            t + 1, nxt, kb2, told or rep, kc2, now,
                            (*seen, (nxt, kc2 == t + 1, rep)))
            values.append(v)
        return pick(values)

    return go(0, GAME.initial, None, False, None, False, ((GAME.initial, False, False),))


def replayed(controller: Any) -> Any:
    from mitld_lp.controllers.observation import Observation

    def act(seen: tuple[Any, ...]) -> str:
        controller.reset()
        action = controller.act(Observation(seen[0][0]))
        for state, cab, told in seen[1:]:
            action = controller.act(Observation(
                state, events=frozenset({"c"} if cab else ()),
                reports=frozenset({"b"} if told else ())))
        return action

    return act


def best_deterministic(pick: Any) -> Fraction:
    """The best worst (best) case of the deterministic observation-based controllers
    that go when they see the cab: a choice at each history at ``mid`` without the cab
    at steps 1 and 2, at most one report of the bus in it (the camera reports once).
    Elsewhere waiting is as good as anything: going at step 0 reaches ``A`` after no
    event, and at step 3 only a cab could come (the bus's hazard is 0 there), seen."""
    histories = []
    for n in (1, 2):
        quiet = (("mid", False, False),) * (n + 1)
        histories.append(quiet)
        histories += [quiet[:j] + (("mid", False, True),) + quiet[j + 1:]
                      for j in range(1, n + 1)]
    assert len(histories) == 5
    best = None
    for choice in itertools.product(("go", "wait"), repeat=len(histories)):
        table = dict(zip(histories, choice, strict=True))

        def act(seen: tuple[Any, ...], table: dict[Any, str] = table) -> str:
            return "go" if seen[-1][1] else table.get(seen, "wait")

        v = value(act, pick)
        best = v if best is None else max(best, v)
    assert best is not None
    return best


@pytest.mark.parametrize("bands, pick", [("worst", min), ("best", max)])
def test_an_unsensed_band_with_no_truncation_point(bands: str, pick: Any) -> None:
    """Solved, not refused: ``lower`` is the returned controller's worst (best) case by
    the enumeration, and the best deterministic controller's lies in the bracket."""
    r = synthesize(model(), bands=bands)
    assert r.route == "sensed" and r.bands and r.controller is not None
    ours = value(replayed(r.controller), pick)
    assert abs(ours - Fraction(r.lower)) <= TOL
    best = best_deterministic(pick)
    assert Fraction(r.lower) <= best + TOL and best <= Fraction(r.upper) + TOL


def test_refused_by_name_where_no_clock_of_the_middle_law_is_exact() -> None:
    """Without the clock reduction the middle law ``pmf [0.3, 0.3]`` (never 0.4) has
    neither a constant hazard nor a truncation point: refused by name, before a state is
    built, not answered."""
    from mitld_lp.distributions.band import UnboundedBand

    with pytest.raises(UnboundedBand, match=r"middle law pmf\(0.3, 0.3\) may never happen"):
        synthesize(model(), clock_reduction=False)


@pytest.mark.skipif(importlib.util.find_spec("stormpy") is None, reason="needs stormpy")
def test_storm_on_the_exported_interval_chain_gives_lower(tmp_path: Path) -> None:
    """Storm's robust check (nature minimising) of the controller's interval chain, the
    cab's outer tail included, gives ``lower``."""
    from test_band_chain import storm_worst

    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

    r = synthesize(model())
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert abs(storm_worst(path) - r.lower) <= 1e-9

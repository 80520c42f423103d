"""``then`` on a band with a constraint used to run for ever (issue 43): the worst case
of the then-policy's constraint met a block of the robust game left only by rare steps
(a policy's go probability of ~1e-9 at a waiting state), which robust interval iteration
closes at about that probability per sweep.  Such blocks are now solved directly
(:meth:`mitld_lp.solvers.robust._Block.evaluate`) and the worst cases run under a sweep
budget (:func:`mitld_lp.solvers.robust.sweep_budget`).

Independent routes: hand values in fractions for the small games; for the three-state
world of the issue the robust optimum by hand, ``1 - 0.7^5 / 2`` (nature's least hazard
0.3 at every step, the robot going at the last step if the bus has not come: h with
probability 1/2), and Storm's robust expected steps on the exported controller chain.
Each end-to-end run is a subprocess with a timeout: a hang fails the test."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.result import Status
from mitld_lp.solvers.robust import robust_interval_iteration, sweep_budget
from mitld_lp.solvers.robust_graph import RobustGame

ROOT = Path(__file__).resolve().parent.parent
EPS = 2.0 ** -33  # 1 - 4 EPS is exact in floats: each row sums to 1


def game(rows: list[list[dict[int, float]]]) -> RobustGame:
    """A robust game from, per state, per choice, nature's rows as {column: p}."""
    data, cols, ptr, vgroups, rgroups = [], [], [0], [0], [0]
    for choices in rows:
        for vertex in choices:
            for row in vertex:
                data += list(row.values())
                cols += list(row)
                ptr.append(len(data))
            vgroups.append(vgroups[-1] + len(vertex))
        rgroups.append(rgroups[-1] + len(choices))
    n = len(rows)
    matrix = sp.csr_array((data, cols, ptr), shape=(len(ptr) - 1, n))
    return RobustGame(matrix, np.array(vgroups), np.array(rgroups))


def test_a_chain_left_by_rare_steps_is_solved_not_iterated():
    """0 -> 1 but for EPS to the target 2 and 3 EPS to the trap 3; 1 -> 0: the value
    of 0 and 1 is EPS / (4 EPS) = 1/4.  Iterated, it would need ~1e10 sweeps; the
    budget of 2500 sweeps is all it may use."""
    g = game([[[{1: 1 - 4 * EPS, 2: EPS, 3: 3 * EPS}]], [[{0: 1.0}]],
              [[{2: 1.0}]], [[{3: 1.0}]]])
    target = np.array([False, False, True, False])
    it = robust_interval_iteration(g, target, max_sweeps=sweep_budget(g, work=1e7))
    assert it.status is Status.OPTIMAL
    for s in (0, 1):
        assert it.lower[s] <= float(Fraction(1, 4)) + 1e-9 <= it.upper[s] + 2e-9
        assert it.upper[s] - it.lower[s] <= 1e-9


def test_a_rare_exit_with_nature_s_choice_closes_both_bounds():
    """The tail's block of the issue: 0 leaves by EPS to 2 (worth 1/2 by its own
    choice: a state of value 1/2) and stays otherwise at 1, whose player (nature,
    maximising) goes back to 0 or to the trap 3.  The best is to go back: the value is
    that of 2, 1/2; iteration alone closes the upper bound at EPS per sweep."""
    g = game([[[{1: 1 - EPS, 2: EPS}]], [[{0: 1.0}], [{3: 1.0}]],
              [[{4: 0.5, 3: 0.5}]], [[{3: 1.0}]], [[{4: 1.0}]]])
    target = np.array([False, False, False, False, True])
    it = robust_interval_iteration(g, target, max_sweeps=sweep_budget(g, work=1e7))
    assert it.status is Status.OPTIMAL
    for s in (0, 1):
        assert it.lower[s] - 1e-9 <= 0.5 <= it.upper[s] + 1e-9
        assert it.upper[s] - it.lower[s] <= 1e-9


def test_the_budget_ends_a_slow_iteration_with_a_status_and_a_sound_bracket():
    """A budget of one sweep: the run ends at once, its status says whether it got
    there, and the bracket holds the hand value 1/2 either way (no silent number)."""
    g = game([[[{1: 1 - EPS, 2: EPS}], [{0: 1.0}]], [[{0: 1.0}], [{1: 1.0}]],
              [[{4: 0.5, 3: 0.5}]], [[{3: 1.0}]], [[{4: 1.0}]]])
    target = np.array([False, False, False, False, True])
    # the robot may also stay put at 0 or 1 for ever (worth 0): still 1/2 at best
    it = robust_interval_iteration(g, target, max_sweeps=1)
    assert it.status in (Status.OPTIMAL, Status.MAX_ITERATIONS)
    assert it.lower[0] <= 0.5 + 1e-12 <= it.upper[0] + 1e-12 + 1e-9
    assert it.status is Status.MAX_ITERATIONS or it.upper[0] - it.lower[0] <= 1e-9


RUN = r"""
import json, sys
sys.path.insert(0, {tests!r})
from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.distributions import geometric
from mitld_lp.distributions.band import band_of_laws
from mitld_lp.running.band_mixture_chain import write_mixture_chain
from test_never_tail import three, UNSETTLED
band = {band}
m = three("D[mu] b & F[0,5] (h | b)", band)
out = {{}}
for key, kw in (("plain", {{}}), ("then", {{"then": "min-steps"}})):
    r = synthesize(m, constraints=["P(F h) <= 0.25"], **kw)
    path = None
    if r.status == "optimal":
        path = str(write_mixture_chain(r, {drn!r} + key + ".drn"))
    out[key] = dict(status=str(r.status), lower=r.lower, upper=r.upper,
                    steps=getattr(r.part, "steps", None), certified=r.certified,
                    failed=[c.name for c in r.checks if not c.passed], drn=path)
print(json.dumps(out))
"""


def run(band: str, tmp_path: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    code = RUN.format(tests=str(ROOT / "tests"), band=band, drn=str(tmp_path / "c_"))
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60, env=env, check=True)
    return json.loads(done.stdout.splitlines()[-1])


def test_then_on_the_issue_s_band_ends_with_the_plain_answer(tmp_path):
    """The reproduction of the issue (notes: 0.5 s without ``then``, > 100 s CPU with
    it): both end; ``lower`` is the hand optimum ``1 - 0.7^5 / 2`` within the
    lexicographic slack ``then`` allows (1e-6 at the middle law, a few times that at the
    worst), as is the run without ``then``; and the answer's E(steps) is Storm's worst
    case on the returned controller's interval chain."""
    out = run('band_of_laws("mu", geometric(0.45), [geometric(0.3), geometric(0.6)])',
              tmp_path)
    exact = float(1 - Fraction(7, 10) ** 5 / 2)
    for key in ("plain", "then"):
        r = out[key]
        assert r["status"] == "optimal" and r["certified"], r
        assert exact - 1e-5 <= r["lower"] <= exact + 1e-9 <= r["upper"] + 2e-9
    assert abs(out["then"]["lower"] - out["plain"]["lower"]) <= 1e-5
    if importlib.util.find_spec("stormpy") is not None:
        from test_band_chain import storm_robust

        storm = storm_robust(Path(out["then"]["drn"]), 'R{"steps"}max=? [F "decided"]',
                             maximise=True)
        assert abs(storm - out["then"]["steps"]) <= 1e-7


def test_then_on_the_tail_band_ends_with_a_status(tmp_path):
    """The tail band of tests/test_never_tail.py (nature may hold the bus off for ever
    past the tail step): without ``then`` the bracket holds the brute-force value; with
    it the run ends in seconds, and either meets every check or says which failed (the
    middle law's fastest policy leaks a tiny "go" while waiting, which a bus held off
    for ever turns into a sure one: its worst P(F h) is above 0.25)."""
    from test_never_tail import brute

    out = run("UNSETTLED", tmp_path)
    exact = float(brute(5, True))
    plain = out["plain"]
    assert plain["status"] == "optimal" and plain["certified"]
    assert plain["lower"] - 1e-9 <= exact <= plain["upper"] + 1e-9
    then = out["then"]
    assert (then["status"] == "optimal") == (not then["failed"]), then
    if then["status"] != "optimal":
        assert "constraints hold against every law of the bands" in then["failed"]

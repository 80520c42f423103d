"""One controller file, one reader (issue 42): a deterministic, a randomised and a
sensed controller, and the files of old (version 1, the sensed format of old), written
here by hand from the format's description (:mod:`mitld_lp.controllers.format`) with
NumPy and JSON, not with the package's writer.  Each hand-made file acts as its tables
say, worked by hand; each is refused for the same faults with the same message by every
loader (``load_controller``, the class's ``load``, ``mitld_lp.runtime.load``); the
runtime and ``mitld-lp run`` serve a synthesised sensed controller as the one in memory
acts, on observations drawn here."""

from __future__ import annotations

import io
import json
import math
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from test_sensing import PMF, SPEC, STATION

from mitld_lp import (
    ConstrainedController,
    Controller,
    ControllerFileError,
    Model,
    Observation,
    RunStatus,
    SensedController,
    load_controller,
    runtime,
    synthesize,
)

ROOT = Path(__file__).resolve().parent.parent
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def _text(value: object) -> np.ndarray:
    return np.frombuffer(json.dumps(value).encode(), dtype=np.uint8)


# A world of two states: "a", and "b" where "goal" holds.  Actions "go" (0), "stay" (1).
# The task's automaton: q0 --goal--> q1 (accepting), q0 --not goal--> q0.
AUTOMATON_META = {"atoms": ["goal"], "events": [], "actions": ["go", "stay"],
                  "clock": {"caps": {}, "truncations": {}}}
ROOTS, NODES = [-1, 1], [[0, 0, 1]]  # q0: node 0 (goal? q1 : q0); q1: the leaf 1


def deterministic(version: int = 4) -> dict[str, np.ndarray]:
    # product states (g, q, pending 0, clock 0) with n_q = 2, no events, one clock
    # value: key = g * 2 + q; (a, q0) has key 0, where the policy says "go" (0)
    meta = {"format": "mitld_lp.running.controller", "version": version, **AUTOMATON_META,
            "automaton": {"initial": 0, "roots": ROOTS, "nodes": NODES,
                          "accepting": 1, "rejecting": None}}
    if version > 1:
        meta.update(kind="deterministic", variables=None)
    return {"meta": _text(meta), "states": _text(["a", "b"]),
            "props": np.array([0, 1], dtype=np.int64),
            "fallback": np.array([1, 1], dtype=np.int32),
            "keys": np.array([0], dtype=np.int64), "policy": np.array([0], dtype=np.int32),
            "hopeless": np.array([False])}


def randomised() -> dict[str, np.ndarray]:
    # at (a, q0): "go" with 1/4, "stay" with 3/4, never stay in an end component
    meta = {"format": "mitld_lp.running.controller", "version": 4, "kind": "randomised",
            "variables": None, **AUTOMATON_META,
            "automaton": {"initial": 0, "roots": ROOTS, "nodes": NODES,
                          "verdicts": [[-1], [1]]}}
    return {"meta": _text(meta), "states": _text(["a", "b"]),
            "props": np.array([0, 1], dtype=np.int64),
            "fallback": np.array([1, 1], dtype=np.int32),
            "keys": np.array([0], dtype=np.int64),
            "offsets": np.array([0, 2], dtype=np.int64),
            "choices": np.array([0, 1], dtype=np.int32),
            "weights": np.array([0.25, 0.75]), "inside": np.array([False, False]),
            "stay": np.array([0.0]), "charged": np.array([True]),
            "keep": np.array([False, False]), "kept": np.array([False, False])}


def sensed(old: bool = False) -> dict[str, np.ndarray]:
    # information state 0 plays "go", 1 plays "stay"; from 0 after "go": at b with e
    # reported -> 1, at a with nothing -> accepted (-1); from 1 after "stay": at b with
    # nothing -> rejected (-2)
    meta = {"events": ["e"], "sensed": ["e"], "ignored": [], "actions": ["go", "stay"],
            "initial": 0}
    if old:
        meta.update(format="mitld-lp-sensed-controller", version=2)
    else:
        meta.update(format="mitld_lp.running.controller", version=4, kind="sensed",
                    variables=None)
    return {"meta": _text(meta), "states": _text(["a", "b"]),
            "first" if old else "fallback": np.array([1, 1], dtype=np.int32),
            "policy": np.array([0, 1], dtype=np.int32),
            "moves": np.array([[0, 0, 1, 1, 1], [0, 0, 0, 0, -1], [1, 1, 1, 0, -2]],
                              dtype=np.int64)}


KINDS: dict[str, Callable[[], dict[str, np.ndarray]]] = {
    "deterministic": deterministic, "deterministic v1": lambda: deterministic(1),
    "randomised": randomised, "sensed": sensed, "sensed of old": lambda: sensed(True)}
CLASSES = {"deterministic": Controller, "randomised": ConstrainedController,
           "sensed": SensedController}


def written(path: Path, members: dict[str, np.ndarray]) -> Path:
    buffer = io.BytesIO()
    np.savez(buffer, **members)  # type: ignore[arg-type]
    path.write_bytes(buffer.getvalue())
    return path


@pytest.mark.parametrize("kind", ["deterministic", "deterministic v1"])
def test_a_hand_made_deterministic_file_acts_as_written(tmp_path: Path, kind: str) -> None:
    path = written(tmp_path / "c.npz", KINDS[kind]())
    for c in (Controller.load(path), load_controller(path)):
        assert isinstance(c, Controller)
        assert c.act(Observation("a")) == "go"  # the policy at (a, q0)
        assert c.act(Observation("a")) == "go"  # q0 again: not the goal
        assert c.act(Observation("b")) is None and c.status is RunStatus.ACCEPTED
        c.reset()
        assert c.act(Observation("b")) is None  # the goal at step 0: accepted at once
        with pytest.raises(ValueError, match="not a state the saved controller knows"):
            c.act(Observation("c"))
    robot = runtime.load(path)
    assert [robot.act("a"), robot.act("b"), robot.status] == ["go", None, "accepted"]


def test_a_hand_made_randomised_file_draws_its_weights(tmp_path: Path) -> None:
    c = ConstrainedController.load(written(tmp_path / "c.npz", randomised()))
    n = 4000
    go = 0
    for seed in range(n):
        c.reset(seed=seed)
        go += c.act(Observation("a")) == "go"
    assert abs(go / n - 0.25) <= 4 * math.sqrt(0.25 * 0.75 / n)


@pytest.mark.parametrize("kind", ["sensed", "sensed of old"])
def test_a_hand_made_sensed_file_follows_its_moves(tmp_path: Path, kind: str) -> None:
    path = written(tmp_path / "c.npz", KINDS[kind]())
    c = load_controller(path)
    assert isinstance(c, SensedController) and c.game is None
    assert c.act(Observation("a")) == "go"
    assert c.act(Observation("b", reports={"e"})) == "stay"
    assert c.act(Observation("b")) is None and c.status is RunStatus.REJECTED
    c.reset()
    assert [c.act(Observation("a")), c.act(Observation("a"))] == ["go", None]
    assert c.status is RunStatus.ACCEPTED
    c.reset()
    c.act(Observation("a"))
    assert c.act(Observation("b")) == "stay" and c.beyond_model  # no such move: fallback
    c.reset()
    c.act(Observation("a"))
    with pytest.raises(ValueError, match="a sensed event through its sensor only"):
        c.act(Observation("b", events={"e"}))
    with pytest.raises(ValueError, match="'x' is not an event of the task"):
        c.act(Observation("b", reports={"x"}))
    out = io.StringIO()
    lines = ['{"state": "a"}', '{"state": "b", "reports": ["e"]}', '{"state": "b"}',
             '{"state": "c"}']
    assert runtime.serve(runtime.load(path), lines, out) == 1
    replies = [json.loads(x) for x in out.getvalue().splitlines()]
    assert [r.get("action") for r in replies[:3]] == ["go", "stay", None]
    assert replies[2]["status"] == "rejected"
    assert "world state 'c': not a state the saved controller knows" in replies[3]["error"]


def _with_meta(members: dict[str, np.ndarray], **changes: object) -> dict[str, np.ndarray]:
    meta = json.loads(members["meta"].tobytes())
    meta.update(changes)
    return {**members, "meta": _text(meta)}


def _fallback(members: dict[str, np.ndarray]) -> str:
    return "first" if "first" in members else "fallback"


def _changed(members: dict[str, np.ndarray], name: str, value: np.ndarray
             ) -> dict[str, np.ndarray]:
    return {**members, name: value}


FAULTS: dict[str, tuple[Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]], str]] = {
    "another version": (lambda m: _with_meta(m, version=99), "format version 99; this "
                        "mitld_lp reads versions "),
    "a foreign format": (lambda m: _with_meta(m, format="other"),
                         "not a controller file (format 'other')"),
    "an action out of range": (
        lambda m: _changed(m, _fallback(m), np.array([1, 7], dtype=np.int32)),
        "fallback: an action number out of range"),
    "a table too short": (lambda m: _changed(m, _fallback(m), np.array([1], dtype=np.int32)),
                          "fallback: expected 2 entries (one per world state)"),
    "a table of two dimensions": (
        lambda m: _changed(m, _fallback(m), np.ones((2, 1), dtype=np.int32)),
        "expected a 1-D int32 array, got int32 (2, 1)"),
    "a table of floats": (lambda m: _changed(m, _fallback(m), np.array([1.0, 1.0])),
                          "expected a 1-D int32 array, got float64"),
    "states that are no JSON": (lambda m: _changed(m, "states", np.frombuffer(
        b'["a", "b"', dtype=np.uint8)), "states: not JSON text"),
    "a state twice": (lambda m: _changed(m, "states", _text(["a", "a"])),
                      "states: a world state appears twice"),
    "a member missing": (lambda m: {k: v for k, v in m.items() if k != "policy"
                                    and k != "offsets"}, "not a controller archive"),
    "an unknown meta key": (lambda m: _with_meta(m, extra=1), "meta: unexpected keys"),
}


@pytest.mark.parametrize("kind", list(KINDS))
@pytest.mark.parametrize("fault", list(FAULTS))
def test_one_reader_refuses_the_same_faults_in_every_kind(tmp_path: Path, kind: str,
                                                          fault: str) -> None:
    change, detail = FAULTS[fault]
    good = written(tmp_path / "good.npz", KINDS[kind]())
    load_controller(good)  # the hand-made file itself is sound
    path = written(tmp_path / "bad.npz", change(KINDS[kind]()))
    cls = CLASSES[kind.split()[0]]
    messages = set()
    for load in (load_controller, cls.load, runtime.load):
        with pytest.raises(ControllerFileError) as err:
            load(path)
        messages.add(str(err.value))
    assert len(messages) == 1, messages  # one reader, one message
    message = messages.pop()
    assert message.startswith(f"{path}: cannot load the controller: ") and detail in message


@pytest.mark.parametrize("kind", list(KINDS))
def test_a_damaged_archive_is_refused_for_every_kind(tmp_path: Path, kind: str) -> None:
    data = written(tmp_path / "good.npz", KINDS[kind]()).read_bytes()
    for cut in (0, 10, len(data) // 2, len(data) - 1):
        path = tmp_path / f"cut{cut}.npz"
        path.write_bytes(data[:cut])
        with pytest.raises(ControllerFileError, match=r"cut\d+.npz: cannot load the "):
            load_controller(path)


@pytest.mark.parametrize("kind, other", [("deterministic", "sensed"), ("sensed", "randomised"),
                                         ("randomised", "deterministic")])
def test_a_class_names_the_kind_it_was_given(tmp_path: Path, kind: str, other: str) -> None:
    path = written(tmp_path / "c.npz", KINDS[other]())
    with pytest.raises(ControllerFileError, match=f"a {other} controller; load it with"):
        CLASSES[kind].load(path)


def test_kind_specific_tables_are_checked(tmp_path: Path) -> None:
    cases = {
        "deterministic": (lambda m: _changed(m, "policy", np.array([5], dtype=np.int32)),
                          "policy: an action number out of range"),
        "randomised": (lambda m: _changed(m, "weights", np.array([0.5, 2.0])),
                       "weights: not probabilities"),
        "sensed": (lambda m: _changed(m, "moves", np.array([[0, 0, 1, 1, 9]])),
                   "moves: a next state out of range"),
        "sensed of old": (lambda m: _changed(m, "moves", np.array([[0, 0, 1, 1, 1, 0]])),
                          "moves: expected rows of 5, got \\(1, 6\\)"),
    }
    for kind, (change, detail) in cases.items():
        path = written(tmp_path / "bad.npz", change(KINDS[kind]()))
        with pytest.raises(ControllerFileError, match=detail):
            load_controller(path)


# --------------------------------------------------------------------------- the runtime


def station_runs(controller: SensedController, runs: int, seed: int, detect: float
                 ) -> list[tuple[list[dict], list[str | None], list[str]]]:
    """Observations of STATION drawn here, in lockstep with ``controller``: the bus at
    step k with PMF (inverse CDF), its report ``j ~ Geometric(detect) - 1`` steps later;
    the world moved by its own successors."""
    rng = np.random.default_rng(seed)
    cdf = np.cumsum(PMF)
    out = []
    for _ in range(runs):
        k = 1 + int(np.searchsorted(cdf, rng.random(), side="right"))
        report = k + int(rng.geometric(detect)) - 1
        controller.reset()
        state, lines, actions, status = STATION.initial, [], [], []
        for t in range(8):
            seen = ["b"] if t == report else []
            lines.append({"state": state, "reports": seen, **({"reset": True} if t == 0
                                                              else {})})
            actions.append(controller.act(Observation(state, reports=seen)))
            status.append(controller.status.value)
            if actions[-1] is None:
                break
            nexts = STATION.successors(state, actions[-1], frozenset())
            u, acc = rng.random(), 0.0
            for nxt, p in nexts:
                acc += p
                if u < acc:
                    state = nxt
                    break
        out.append((lines, actions, status))
    return out


def test_mitld_lp_run_serves_a_sensed_controller(tmp_path: Path) -> None:
    """Issue 43 asks ``mitld-lp run`` to run sensed controllers: it refused them ("do not
    serve it yet"); the one reader reads them and the one step rule runs them."""
    r = synthesize(Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.6}}))
    assert r.route == "sensed"
    path = r.controller.save(tmp_path / "sensed.npz")
    runs = station_runs(r.controller, runs=40, seed=3, detect=0.6)
    assert {s[-1] for _, _, s in runs} >= {"accepted", "rejected"}
    text = "".join(json.dumps(x) + "\n" for lines, _, _ in runs for x in lines)
    done = subprocess.run([sys.executable, "-m", "mitld_lp", "run", str(path)], input=text,
                          env=ENV, capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    replies = [json.loads(x) for x in done.stdout.splitlines()]
    assert [x["action"] for x in replies] == [a for _, acts, _ in runs for a in acts]
    assert [x["status"] for x in replies] == [s for _, _, st in runs for s in st]

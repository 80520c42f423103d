"""Controllers: saved as data and loaded without running anything from the file, in a
process that lacks the world's class; pickling in memory (for multiprocessing) still
acts the same; observations are checked."""

from __future__ import annotations

import io
import json
import os
import pickle
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mitld_lp import GridWorld, Model, Observation, RunStatus, synthesize
from mitld_lp.controllers.format import ControllerFileError, decode_state, encode_state
from mitld_lp.controllers.kinds import Controller
from mitld_lp.distributions import weibull
from mitld_lp.model import load_model
from mitld_lp.product import ProductState
from mitld_lp.running.simulate import rollout, simulate
from mitld_lp.worlds.game import ExplicitGame, check_game

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"


def roundtrip(obj):
    return pickle.loads(pickle.dumps(obj))


# --------------------------------------------------------------------------- a test world


def shuttle_world():
    """A shuttle on cells 0..4 behind a door at cell 2 that opens with the event "open";
    its battery drains 1/16 a step (exact in binary).  A state is ``((cell, "lane"),
    door open, battery)``: nested tuples of int, str, bool and float.  The class is
    made inside this function, so no other process can import it."""

    class Shuttle:
        initial = ((0, "lane"), False, 1.0)
        proposition_names = frozenset({"goal", "low"})
        event_names = frozenset({"open"})

        def actions(self, state):
            (cell, _), _, battery = state
            if battery <= 0.0:
                return ("wait",)
            return ("go", "wait", "back") if cell > 0 else ("go", "wait")

        def successors(self, state, action, events):
            (cell, lane), door, battery = state
            door = door or "open" in events
            battery = max(0.0, battery - 0.0625)

            def at(c):
                return ((c, lane), door, battery)

            if action == "go" and cell < 4 and (cell != 2 or door):
                return ((at(cell + 1), 0.8), (at(cell), 0.2))
            if action == "back":
                return ((at(cell - 1), 1.0),)
            return ((at(cell), 1.0),)

        def propositions(self, state):
            (cell, _), _, battery = state
            return frozenset({"goal"} if cell == 4 else ()) | frozenset(
                {"low"} if battery <= 0.25 else ())

    return Shuttle()


def shuttle_result():
    world = shuttle_world()
    # A Weibull wait is truncated (epsilon 0.2): runs outlive the model, where the
    # world reaches states the product never built.
    model = Model.from_game(world, "D[w] open & (!low U (open & F[0,3] goal))",
                            distributions={"w": weibull(2.0, 3.0)}, epsilon=0.2)
    return world, synthesize(model)


def recorded_runs(world, result, runs, seed):
    """Rollouts in the untruncated world: per run the observations and the in-memory
    controller's actions, and how many runs went past a truncation point."""
    rng = np.random.default_rng(seed)
    out, beyond = [], 0
    for _ in range(runs):
        status, steps = rollout(result.model, result.controller, rng, max_steps=40,
                                record=True)
        beyond += result.controller.beyond_model
        out.append(([(s.state, sorted(s.events)) for s in steps],
                     [s.action for s in steps], status.value))
    return out, beyond


def to_json(state):
    """A state as JSON, written here independently of the package's encoder."""
    return [to_json(s) for s in state] if isinstance(state, tuple) else state


LOAD_AND_RUN = r"""
import json, sys
from mitld_lp import Controller, Observation

def state(v):
    return tuple(state(x) for x in v) if isinstance(v, list) else v

controller = Controller.load(sys.argv[1])
answers = []
for observations in json.load(open(sys.argv[2])):
    controller.reset()
    acts = [controller.act(Observation(state(s), frozenset(e))) for s, e in observations]
    answers.append([acts, controller.status.value])
solvers = sorted(m for m in ("cvxpy", "clarabel", "highspy", "stormpy") if m in sys.modules)
print(json.dumps({"answers": answers, "solvers": solvers}))
"""


def test_saved_controller_runs_in_a_process_without_the_world_class(tmp_path: Path) -> None:
    world, result = shuttle_result()
    runs, beyond = recorded_runs(world, result, runs=300, seed=5)
    assert beyond > 10  # the comparison covers runs past the model, not only inside it
    assert {status for _, _, status in runs} >= {"accepted", "rejected"}
    path = result.controller.save(tmp_path / "shuttle.npz")
    (tmp_path / "runs.json").write_text(json.dumps(
        [[(to_json(s), e) for s, e in observations] for observations, _, _ in runs]))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = str(ROOT)
    done = subprocess.run(
        [sys.executable, "-c", LOAD_AND_RUN, str(path), str(tmp_path / "runs.json")],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    reply = json.loads(done.stdout)
    assert reply["solvers"] == []
    for (_, actions, status), (theirs, their_status) in zip(runs, reply["answers"],
                                                              strict=True):
        assert theirs == actions and their_status == status


@pytest.mark.parametrize("name", ["bus_grid.toml", "red_light.toml", "corridor.toml"])
def test_loaded_controller_acts_as_the_original_on_the_bundled_models(
        tmp_path: Path, name: str) -> None:
    m = load_model(MODELS / name)
    r = synthesize(m)
    copy = Controller.load(r.controller.save(tmp_path / "c.npz"))
    rng = np.random.default_rng(2)
    for _ in range(200):
        status, steps = rollout(m, r.controller, rng, max_steps=60, record=True)
        copy.reset()
        assert [copy.act(Observation(s.state, s.events)) for s in steps] == [
            s.action for s in steps]
        assert copy.status is status
        assert copy.beyond_model == r.controller.beyond_model


def test_loaded_controller_follows_the_policy_table_state_by_state(tmp_path: Path) -> None:
    """Every product state's action, read from the MDP and the policy directly (not
    through a controller), is what the loaded controller answers there."""
    m = load_model(MODELS / "bus_grid.toml")
    r = synthesize(m)
    copy = Controller.load(r.controller.save(tmp_path / "c.npz"))
    plan = copy._plan  # the tables; asked state by state without a run
    checked = 0
    for i, s in enumerate(r.mdp.states):
        if isinstance(s, ProductState) and r.lower_model.policy[i] >= 0:
            action, _ = plan.lookup(s.game, s.automaton, s.pending, s.clock)
            assert action == r.mdp.action_names[r.mdp.choice_actions[r.lower_model.policy[i]]]
            checked += 1
    assert checked > 300


# --------------------------------------------------------------------------- nothing runs


class _Payload:
    """Unpickling this creates the file ``marker`` (a stand-in for os.system)."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (open, (str(self.marker), "w"))


def malicious_files(tmp_path: Path, marker: Path) -> list[Path]:
    evil = pickle.dumps(_Payload(marker))
    files = {
        "evil.pkl": evil,
        "evil.npz": evil,  # the same bytes under the controller's suffix
        "old_format.npz": pickle.dumps(("mitld_lp.Controller/1", _Payload(marker))),
    }
    out = []
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
        out.append(tmp_path / name)
    # a NumPy archive / array whose members are pickled objects
    members = io.BytesIO()  # every member a controller has, one of them pickled
    arrays: dict[str, np.ndarray] = {
        k: np.zeros(0, dtype=np.int64)
        for k in ("states", "props", "fallback", "keys", "policy", "hopeless")}
    arrays["meta"] = np.array([_Payload(marker)], dtype=object)
    np.savez(members, **arrays)  # type: ignore[arg-type]
    (tmp_path / "object_member.npz").write_bytes(members.getvalue())
    array = io.BytesIO()
    np.save(array, np.array([_Payload(marker)], dtype=object))
    (tmp_path / "object_array.npy").write_bytes(array.getvalue())
    return [*out, tmp_path / "object_member.npz", tmp_path / "object_array.npy"]


def test_a_crafted_file_is_refused_and_runs_nothing(tmp_path: Path) -> None:
    armed = tmp_path / "armed"
    pickle.loads(pickle.dumps(_Payload(armed)))  # the payload does fire when unpickled
    assert armed.exists()
    marker = tmp_path / "marker"
    for path in malicious_files(tmp_path, marker):
        with pytest.raises(ControllerFileError) as err:
            Controller.load(path)
        message = str(err.value)
        assert message.startswith(f"{path}: cannot load the controller") and "\n" not in message
        assert isinstance(err.value, ValueError)
        assert not marker.exists(), path.name


# --------------------------------------------------------------------------- damaged files


def saved_bus_grid(tmp_path: Path) -> Path:
    return synthesize(load_model(MODELS / "bus_grid.toml")).controller.save(tmp_path / "ok.npz")


def rewritten(path: Path, out: Path, change) -> Path:
    """``path``'s archive with its members passed through ``change(dict) -> dict``."""
    with np.load(path, allow_pickle=False) as z:
        members = {k: z[k] for k in z.files}
    buffer = io.BytesIO()
    np.savez(buffer, **change(members))
    out.write_bytes(buffer.getvalue())
    return out


def with_meta(members: dict, **changes) -> dict:
    meta = json.loads(members["meta"].tobytes())
    meta.update(changes)
    return {**members, "meta": np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)}


def test_damaged_truncated_or_foreign_files_are_one_clear_error(tmp_path: Path) -> None:
    good = saved_bus_grid(tmp_path)
    Controller.load(good)  # the original loads
    data = good.read_bytes()
    cases: dict[str, tuple[Path, str]] = {}
    for cut in (0, 10, len(data) // 2, len(data) - 1):
        p = tmp_path / f"cut{cut}.npz"
        p.write_bytes(data[:cut])
        cases[f"truncated at {cut}"] = (p, "")
    flipped = bytearray(data)
    with zipfile.ZipFile(good) as z:  # a byte inside the compressed policy keys
        info = z.getinfo("keys.npy")
    local = info.header_offset
    name_len = int.from_bytes(data[local + 26:local + 28], "little")
    extra_len = int.from_bytes(data[local + 28:local + 30], "little")
    flipped[local + 30 + name_len + extra_len + info.compress_size // 2] ^= 0xFF
    (tmp_path / "flipped.npz").write_bytes(bytes(flipped))
    cases["a flipped byte"] = (tmp_path / "flipped.npz", "")
    (tmp_path / "text.npz").write_text("name = 'bus_grid'\n")
    cases["a text file"] = (tmp_path / "text.npz", "")
    cases["a folder"] = (tmp_path, "")
    cases["no file"] = (tmp_path / "missing.npz", "No such file")
    cases["version 6"] = (rewritten(good, tmp_path / "v6.npz",
                                    lambda m: with_meta(m, version=6)),
                          "format version 6; this mitld_lp reads versions 1, 2, 3, 4, 5")
    cases["another format"] = (rewritten(good, tmp_path / "fmt.npz",
                                         lambda m: with_meta(m, format="other")),
                               "not a controller file")
    cases["a member missing"] = (rewritten(good, tmp_path / "miss.npz",
                                           lambda m: {k: v for k, v in m.items()
                                                      if k != "keys"}), "not a controller archive")
    cases["float keys"] = (rewritten(good, tmp_path / "dtype.npz",
                                     lambda m: {**m, "keys": m["keys"].astype(float)}),
                           "keys: expected a 1-D int64 array")
    cases["short props"] = (rewritten(good, tmp_path / "short.npz",
                                      lambda m: {**m, "props": m["props"][:-1]}),
                            "one per world state")
    cases["unsorted keys"] = (rewritten(good, tmp_path / "order.npz",
                                        lambda m: {**m, "keys": m["keys"][::-1].copy()}),
                              "not strictly increasing")
    cases["an action out of range"] = (
        rewritten(good, tmp_path / "act.npz",
                  lambda m: {**m, "policy": np.full_like(m["policy"], 99)}),
        "policy: an action number out of range")

    def cycle(m: dict) -> dict:
        meta = json.loads(m["meta"].tobytes())
        meta["automaton"]["nodes"][0][1] = -len(meta["automaton"]["nodes"]) - 1
        return with_meta(m, automaton=meta["automaton"])

    cases["a diagram node pointing forwards"] = (rewritten(good, tmp_path / "cycle.npz", cycle),
                                                 "not an earlier one")
    cases["a state that is no state"] = (
        rewritten(good, tmp_path / "state.npz",
                  lambda m: {**m, "states": np.frombuffer(b'[{"x": 1}]', dtype=np.uint8)}),
        "states:")
    raw = tmp_path / "raw.npz"
    with zipfile.ZipFile(raw, "w") as z:  # every member, none of them an array
        for name in ("meta", "states", "props", "fallback", "keys", "policy", "hopeless"):
            z.writestr(name, b"[]")
    cases["members that are no arrays"] = (raw, "not a NumPy array")
    for what, (path, detail) in cases.items():
        with pytest.raises(ControllerFileError) as err:
            Controller.load(path)
        message = str(err.value)
        assert message.startswith(f"{path}: cannot load the controller: "), what
        assert detail in message and "\n" not in message and len(message) < 400, (what, message)


# --------------------------------------------------------------------------- saving


def test_save_refuses_to_overwrite_and_worlds_it_cannot_encode(tmp_path: Path) -> None:
    path = saved_bus_grid(tmp_path)
    r = synthesize(load_model(MODELS / "bus_grid.toml"))
    with pytest.raises(FileExistsError, match="overwrite=True"):
        r.controller.save(path)
    r.controller.save(path, overwrite=True)

    cell = frozenset({1})  # hashable, but not one of the encoded kinds
    odd = ExplicitGame(initial=cell, transitions={cell: {"a": {cell: 1.0}}},
                       labels={cell: {"A"}})
    result = synthesize(Model.from_game(odd, "F[0,2] A"))
    target = tmp_path / "odd.npz"
    with pytest.raises(ValueError, match=r"world state frozenset\(\{1\}\): cannot be saved"):
        result.controller.save(target)
    assert not target.exists()
    with pytest.raises(ValueError, match="max_states"):
        r.controller.save(tmp_path / "small.npz", max_states=10)
    assert not (tmp_path / "small.npz").exists()


def test_a_loaded_controller_saves_again_and_refuses_states_it_does_not_know(
        tmp_path: Path) -> None:
    copy = Controller.load(saved_bus_grid(tmp_path))
    again = Controller.load(copy.save(tmp_path / "again.npz"))
    copy.reset()
    first = Observation(state=(0, 0))
    assert again.act(first) == copy.act(first)
    again.reset()
    with pytest.raises(ValueError, match=r"world state \(9, 9\): not a state the saved"):
        again.act(Observation(state=(9, 9)))


scalars = st.one_of(st.none(), st.booleans(), st.integers(),
                    st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=5))
states = st.recursive(scalars, lambda inner: st.tuples(inner, inner) | st.tuples(inner),
                      max_leaves=8)


@given(states)
def test_world_states_round_trip_exactly_through_json(state) -> None:
    back = decode_state(json.loads(json.dumps(encode_state(state))))
    assert repr(back) == repr(state)  # the same types and digits, -0.0 included
    assert back == state and hash(back) == hash(state)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), frozenset({1}), (1, [2]),
                                 {"a": 1}, b"x", object()])
def test_states_that_are_not_data_are_refused(bad) -> None:
    with pytest.raises(ValueError, match="world state"):
        encode_state(bad)


# --------------------------------------------------------------------------- observations


def test_observation_events_must_be_a_collection_of_names() -> None:
    with pytest.raises(TypeError, match=r"got the string 'A'; write events=\{'A'\}"):
        Observation((0, 0), events="A")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="an event name is a string"):
        Observation((0, 0), events={1})  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="hashable"):
        Observation([0, 0])  # type: ignore[arg-type]
    assert Observation((0, 0), events=["b1", "b2"]).events == frozenset({"b1", "b2"})  # type: ignore[arg-type]


# --------------------------------------------------------------------------- pickling in memory


def test_explicit_game_pickles_with_its_tables():
    g = ExplicitGame(
        initial=0,
        transitions={0: {"a": {1: 1.0}, "b": {0: 0.25, 1: 0.75}}, 1: {"a": {0: 1.0}}},
        labels={1: {"A"}},
        event_transitions={(0, "a", frozenset({"e"})): {0: 1.0}},
    )
    h = roundtrip(g)
    assert h == g and hash(h) == hash(g)
    assert h.successors(0, "a", frozenset({"e"})) == ((0, 1.0),)
    assert h.successors(0, "b", frozenset()) == ((0, 0.25), (1, 0.75))
    assert h.propositions(1) == frozenset({"A"}) and h.proposition_names == frozenset({"A"})
    assert check_game(h, events=["e"]) == check_game(g, events=["e"])


def test_grid_world_pickles_after_use():
    g = GridWorld.make(5, 4, start=(1, 1), slip=0.1, obstacles=[(2, 2)],
                       regions={"A": [(0, 3)]}, stay=True)
    g.successors((1, 1), "N", frozenset())  # fills the lazy cache
    h = roundtrip(g)
    assert h == g and hash(h) == hash(g)
    for cell in g.cells:
        for a in g.actions(cell):
            assert h.successors(cell, a, frozenset()) == g.successors(cell, a, frozenset())
        assert h.propositions(cell) == g.propositions(cell)


@pytest.mark.parametrize("name", ["bus_grid.toml", "red_light.toml"])  # red_light: truncated
def test_controller_pickled_in_memory_acts_the_same(name):
    """Pickle stays for handing a controller to another process of the same program
    (multiprocessing); it is not the file format."""
    m = load_model(MODELS / name)
    r = synthesize(m)
    sta = roundtrip(r.sta)
    assert sta.truncation_points == r.sta.truncation_points
    for q in range(sta.dta.n_states):
        assert sta.dta.delta[q] == r.sta.dta.delta[q]
    copy = roundtrip(r.controller)
    a = simulate(m, r.controller, runs=200, seed=3)
    b = simulate(roundtrip(m), copy, runs=200, seed=3)
    assert (a.successes, a.beyond_model, a.undecided) == (b.successes, b.beyond_model, b.undecided)
    copy.reset()
    r.controller.reset()
    first = Observation(state=m.game.initial)
    assert copy.act(first) == r.controller.act(first)
    assert copy.status is r.controller.status is RunStatus.RUNNING

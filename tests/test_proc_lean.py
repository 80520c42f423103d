"""proc-lean's cuts of the PRISM route's process: the file parsed once with the labels a
model file defines, and NumPy's and SciPy's OpenBLAS pools idle at once when the package
loads them.

The world loaded is checked against a brute-force explorer written here in Python from
the program's text (no Storm): its reachable valuations, each one's actions, moves and
propositions (the file's label, its Boolean formula, the labels defined).  The labels
Storm builds in one parse are the ones the steps of old make (the file parsed as
written, the labels added, parsed again), with the same errors.  The OpenBLAS setting is
read back from each library (``openblas_thread_timeout``, what the library read from
the environment when loaded) in a fresh interpreter."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import pytest

from mitld_lp.util import blas_idle

needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy: pip install -e '.[prism]'")

ROOT = Path(__file__).resolve().parents[1]

N = 3
# Two modules synchronising on [go]; [back] and [flip] are one module's alone.
DOOR = f"""mdp
const int N = {N};
{{formula}}
module robot
  x : [0..N] init 0;
  [go]   x < N -> 0.75 : (x'=x+1) + 0.25 : (x'=x);
  [back] x > 0 -> (x'=x-1);
endmodule
module door
  d : bool init false;
  [go] true -> 0.5 : (d'=!d) + 0.5 : (d'=d);
  [flip] !d -> (d'=true);
endmodule
label "open" = d;
"""
WITH_FORMULA = DOOR.replace("{formula}", "formula full = x = N;\nformula twice = 2*x;")
WITHOUT_FORMULA = DOOR.replace("{formula}", "formula twice = 2*x;")
DEFINE = {"far": "x >= 2 & !d", "even": "twice = 2 | twice = 0 | twice = 4 | twice = 6"}


def brute_force(boolean_formula: bool) -> dict[tuple[int, bool], dict]:
    """Every reachable (x, d) of DOOR from (0, false), breadth first, with its actions'
    distributions (exact) and its propositions, from the program's semantics written
    out by hand (the synchronised [go] is the product of both modules' choices)."""
    def moves(x: int, d: bool) -> dict[str, dict[tuple[int, bool], Fraction]]:
        out: dict[str, dict[tuple[int, bool], Fraction]] = {}
        if x < N:
            go: dict[tuple[int, bool], Fraction] = {}
            for nx, px in ((x + 1, Fraction(3, 4)), (x, Fraction(1, 4))):
                for nd, pd in ((not d, Fraction(1, 2)), (d, Fraction(1, 2))):
                    go[(nx, nd)] = go.get((nx, nd), Fraction(0)) + px * pd
            out["go"] = go
        if x > 0:
            out["back"] = {(x - 1, d): Fraction(1)}
        if not d:
            out["flip"] = {(x, True): Fraction(1)}
        return out

    def props(x: int, d: bool) -> frozenset[str]:
        truth = {"open": d, "far": x >= 2 and not d, "even": 2 * x in (0, 2, 4, 6)}
        if boolean_formula:
            truth["full"] = x == N
        return frozenset(k for k, v in truth.items() if v)

    seen = {(0, False): None}
    queue = [(0, False)]
    world = {}
    while queue:
        state = queue.pop(0)
        m = moves(*state)
        world[state] = dict(moves=m, props=props(*state))
        for dist in m.values():
            for t in dist:
                if t not in seen:
                    seen[t] = None
                    queue.append(t)
    return world


@needs_storm
@pytest.mark.parametrize("text, formula", [(WITH_FORMULA, True), (WITHOUT_FORMULA, False)])
def test_the_world_is_the_brute_force_explorers(tmp_path: Path, text: str,
                                                formula: bool) -> None:
    from mitld_lp.worlds.prism import load_prism

    src = tmp_path / "door.prism"
    src.write_text(text)
    game = load_prism(src, define=DEFINE)
    expected = brute_force(formula)

    def key(state: tuple) -> tuple[int, bool]:
        v = game.valuation(state)
        return int(v["x"]), bool(v["d"])

    assert sorted(map(key, game.states)) == sorted(expected)
    assert key(game.initial) == (0, False)
    names = {"open", "far", "even"} | ({"full"} if formula else set())
    assert game.proposition_names == names
    for state in game.states:
        want = expected[key(state)]
        assert game.propositions(state) == want["props"], key(state)
        assert set(game.actions(state)) == set(want["moves"]), key(state)
        for action, dist in want["moves"].items():
            got: dict[tuple[int, bool], float] = {}
            for t, p in game.successors(state, action, frozenset()):
                got[key(t)] = got.get(key(t), 0.0) + p
            assert set(got) == set(dist), (key(state), action)
            for t, p in dist.items():
                assert abs(got[t] - float(p)) <= 1e-15, (key(state), action, t)
            # Storm's exact build of the program as loaded (labels parsed in once too)
            exact: dict[tuple[int, bool], Fraction] = {}
            for t, p in game.exact_successors(state, action, frozenset()):
                exact[key(t)] = exact.get(key(t), Fraction(0)) + Fraction(p)
            assert exact == dist, (key(state), action)


def _labels(program) -> list[tuple[str, str]]:
    return [(lab.name, str(lab.expression)) for lab in program.labels]


@needs_storm
@pytest.mark.parametrize("text, parses", [(WITHOUT_FORMULA, 1), (WITH_FORMULA, 2)])
def test_one_parse_makes_the_steps_program(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                           text: str, parses: int) -> None:
    """With labels defined, Storm parses the file once (twice when a Boolean formula is
    added as a label too), and the program has the labels the old steps give it."""
    import stormpy

    from mitld_lp.worlds import prism_program as pp

    src = tmp_path / "door.prism"
    src.write_text(text)
    old = pp.parse_program(stormpy, str(src), "door")
    extra = pp.extra_labels(old, dict(DEFINE), "door")
    old = pp.with_labels(stormpy, src, extra, "door")

    calls: list[str] = []
    parse = stormpy.parse_prism_program

    def counted(path: str, *args: object, **kwargs: object) -> object:
        calls.append(path)
        return parse(path, *args, **kwargs)

    monkeypatch.setattr(stormpy, "parse_prism_program", counted)
    checked: list[object] = []
    new = pp.labelled_program(stormpy, src, str(src), DEFINE, "door", check=checked.append)
    assert len(calls) == parses
    assert checked == [new]
    assert _labels(new) == _labels(old)
    assert [lab.name for lab in new.labels][-2:] == list(DEFINE)


@needs_storm
@pytest.mark.parametrize("define, message", [
    ({"open": "x=1"}, "already has a label 'open'"),
    ({"full": "x=1"}, "already has a formula 'full'"),
    ({"bad": "x=1 &"}, "PRISM parse error"),
    ({"9x": "x=1"}, "not a PRISM identifier"),
    ({"two": "x=1; label \"y\" = true"}, "must be one PRISM expression"),
])
def test_a_refused_label_gets_the_steps_error(tmp_path: Path, define: dict[str, str],
                                              message: str) -> None:
    import stormpy

    from mitld_lp.worlds import WorldError
    from mitld_lp.worlds import prism_program as pp

    src = tmp_path / "door.prism"
    src.write_text(WITH_FORMULA)
    with pytest.raises(WorldError, match=message):
        pp.labelled_program(stormpy, src, str(src), define, "door")


@needs_storm
def test_the_model_type_is_checked_before_a_label(tmp_path: Path) -> None:
    """A dtmc with a label that is refused: the model type's error, as before."""
    from mitld_lp.worlds import WorldError
    from mitld_lp.worlds.prism import load_prism

    src = tmp_path / "chain.prism"
    src.write_text("dtmc\nmodule m\n  x : [0..1] init 0;\n  [] x=0 -> (x'=1);\nendmodule\n")
    with pytest.raises(WorldError, match="the model is a DTMC"):
        load_prism(src, define={"x1": "x=1"})
    with pytest.raises(WorldError, match="the model is a DTMC"):
        load_prism(src, define={"bad": "x=1 &"})


# --------------------------------------------------------------------------- OpenBLAS


class _Recorder:
    """A loader standing in for an extension module's: what the environment said of
    the setting while the module was created."""

    def __init__(self, inner: object = None) -> None:
        self.seen: list[str | None] = []
        self.inner = inner

    def create_module(self, spec: object) -> None:
        self.seen.append(os.environ.get(blas_idle.SETTING))
        if self.inner is not None:  # an extension whose init imports another one
            self.inner.create_module(_Spec())

    def exec_module(self, module: object) -> None:
        pass


class _Spec:
    loader: object = None


@pytest.fixture
def clean_blas_env(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in blas_idle.USER_SETTINGS:
        monkeypatch.delenv(name, raising=False)


def test_the_setting_holds_for_the_load_alone(clean_blas_env: None,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    # the process alone in its one Python thread (an earlier test in this worker may
    # have left one running; the other-thread rule has its own test below)
    monkeypatch.setattr(blas_idle.threading, "active_count", lambda: 1)
    inner = _Recorder()
    outer = _Recorder(blas_idle.IdleLoader(inner))
    spec = _Spec()
    blas_idle.IdleLoader(outer).create_module(spec)
    assert outer.seen == [blas_idle.TIMEOUT] and inner.seen == [blas_idle.TIMEOUT]
    assert spec.loader is outer  # the module keeps its own loader
    assert blas_idle.SETTING not in os.environ


@pytest.mark.parametrize("name", blas_idle.USER_SETTINGS)
def test_a_users_setting_is_left_alone(clean_blas_env: None, monkeypatch: pytest.MonkeyPatch,
                                       name: str) -> None:
    monkeypatch.setenv(name, "2")
    seen = _Recorder()
    blas_idle.IdleLoader(seen).create_module(_Spec())
    assert seen.seen == [os.environ.get(blas_idle.SETTING)]
    assert os.environ[name] == "2" and (name == blas_idle.SETTING
                                        or blas_idle.SETTING not in os.environ)


def test_no_setting_while_another_thread_runs(clean_blas_env: None) -> None:
    import threading

    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        seen = _Recorder()
        blas_idle.IdleLoader(seen).create_module(_Spec())
    finally:
        stop.set()
        other.join()
    assert seen.seen == [None] and blas_idle.SETTING not in os.environ


def test_a_failed_load_puts_the_environment_back(clean_blas_env: None) -> None:
    class Failing(_Recorder):
        def create_module(self, spec: object) -> None:
            super().create_module(spec)
            raise ImportError("no such library")

    with pytest.raises(ImportError):
        blas_idle.IdleLoader(Failing()).create_module(_Spec())
    assert blas_idle.SETTING not in os.environ


PROBE = r"""
import ctypes, glob, json, os, sys
first = sys.argv[1]
if first == "numpy":
    import numpy
import mitld_lp
from mitld_lp import synthesis  # the package's first module: its import window
import numpy, scipy.linalg
out = {"env": os.environ.get("OPENBLAS_THREAD_TIMEOUT")}
fblas = sys.modules["scipy.linalg._fblas"]  # an extension module: its own loader kept
out["loader"] = sorted({type(fblas.__loader__).__name__, type(fblas.__spec__.loader).__name__})
for pkg, pattern in (("numpy", "numpy.libs/libscipy_openblas*.so"),
                     ("scipy", "scipy.libs/libscipy_openblas*.so")):
    root = os.path.dirname(os.path.dirname(sys.modules[pkg].__file__))
    found = sorted(glob.glob(os.path.join(root, pattern)))
    out[pkg] = ctypes.CDLL(found[0]).openblas_thread_timeout() if found else None
print(json.dumps(out))
"""


def _probe(first: str, **env: str) -> dict:
    clean = {k: v for k, v in os.environ.items()
             if k not in blas_idle.USER_SETTINGS and k != "MITLD_LP_PLAIN_IMPORTS"}
    clean["PYTHONPATH"] = str(ROOT)
    clean.update(env)
    out = subprocess.run([sys.executable, "-c", PROBE, first], env=clean, cwd=ROOT,
                         capture_output=True, text=True, check=True, timeout=300)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_libraries_read_the_setting_when_the_package_loads_them() -> None:
    """A program importing the package first: both libraries loaded idle; NumPy
    imported before the package: its library as NumPy made it, SciPy's idle; the
    environment without the setting after; plain imports or a user's setting: none."""
    late = _probe("package")
    if late["numpy"] is None or late["scipy"] is None:
        pytest.skip("this NumPy or SciPy does not bundle OpenBLAS")
    own = {"env": None, "loader": ["ExtensionFileLoader"]}
    assert late == {**own, "numpy": 4, "scipy": 4}
    assert _probe("numpy") == {**own, "numpy": 0, "scipy": 4}
    assert _probe("package", MITLD_LP_PLAIN_IMPORTS="1") == {**own, "numpy": 0, "scipy": 0}
    assert _probe("package", OPENBLAS_NUM_THREADS="1") == {**own, "numpy": 0, "scipy": 0}

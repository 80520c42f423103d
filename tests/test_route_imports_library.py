"""A program importing the package (``mitld_lp.library_start``): a PRISM route leaves
NumPy's extra submodules unloaded and makes the package's own dataclasses without
``exec``, and nobody else's; the answers are the same to the bit, and Storm's."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

#: A robot at cell 0 of 0..3 must reach cell 3 (4 is a trap).  Move ``a``: forward 0.6,
#: trap 0.1, stay 0.3, so forward before the trap with 0.6 / 0.7 = 6/7; move ``b``:
#: forward 0.8, trap 0.2.  ``a`` is the better each step: Pmax = (6/7)^3.
PRISM = """mdp
module robot
  x : [0..4] init 0;
  [a] x < 3 -> 0.6 : (x'=x+1) + 0.1 : (x'=4) + 0.3 : (x'=x);
  [b] x < 3 -> 0.8 : (x'=x+1) + 0.2 : (x'=4);
endmodule
label "goal" = x = 3;
"""
VALUE = (6 / 7) ** 3

#: Modules the library route of a PRISM file need not load: NumPy's submodules that
#: SciPy's array-API layer would import when it copies NumPy's namespace.
UNLOADED = ("numpy.f2py", "numpy.testing", "numpy.polynomial", "numpy.ctypeslib",
            "numpy.rec", "numpy.char", "numpy.strings")

#: The route as a program runs it (argv[2]: "hooked", the program asking for the hook
#: before anything else is imported, or "plain", as imported); prints the answer, the modules
#: loaded, how dataclasses were made, and SciPy's copy of NumPy's namespace.
PROBE = r"""
import json, sys
import mitld_lp
from mitld_lp import library_start
plain_import = sorted(m for m in ("numpy", "dataclasses", "scipy") if m in sys.modules)
unasked = library_start.installed()
if sys.argv[2] == "hooked":
    library_start.install()
waiting = library_start.installed()
from dataclasses import dataclass
@dataclass(frozen=True)
class Mine:
    x: int
from mitld_lp import load_model, synthesize
r = synthesize(load_model(sys.argv[1]))
loaded = sorted(m for m in json.loads(sys.argv[3]) if m in sys.modules)
left = library_start.waiting_for()
import numpy
from scipy._lib.array_api_compat import numpy as copy
from mitld_lp.logic.syntax import Prop
same = [getattr(copy, n) is getattr(numpy, n) for n in ("f2py", "testing", "ma", "polynomial")]
print(json.dumps(dict(
    answer=[r.lower.hex(), r.upper.hex(), r.certified], waiting=waiting,
    plain_import=plain_import, loaded=loaded, left=left,
    mine=[Mine.__eq__.__code__.co_filename, Mine.__init__.__code__.co_filename,
          repr(Mine(1)), Mine(1) == Mine(1), hash(Mine(1)) == hash((1,))],
    ours=[Prop.__eq__.__code__.co_filename == "<string>", repr(Prop("goal"))],
    unasked=unasked, copy_all=sorted(copy.__all__), copy_dir=sorted(dir(copy)), same=same,
    numpy_all=sorted(numpy.__all__))))
"""


def _route(model: Path, how: str) -> dict:
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONDONTWRITEBYTECODE", "MITLD_LP_PLAIN_IMPORTS")}
    if how == "plain":  # the imports exactly as Python makes them (mitld_lp.own_imports out)
        env["MITLD_LP_PLAIN_IMPORTS"] = "1"
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    done = subprocess.run([sys.executable, "-c", PROBE, str(model), how, json.dumps(UNLOADED)],
                          cwd=model.parent, env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict]:
    pytest.importorskip("stormpy")
    where = tmp_path_factory.mktemp("route")
    (where / "robot.prism").write_text(PRISM, encoding="utf-8")
    model = where / "robot.toml"
    model.write_text('name = "robot"\nspec = "F goal"\nobjective = "max"\n\n'
                     '[prism]\nfile = "robot.prism"\n', encoding="utf-8")
    return {how: _route(model, how) for how in ("hooked", "default", "plain")}


def test_the_library_route_leaves_numpys_extras_unloaded(runs: dict[str, dict]) -> None:
    hooked, plain = runs["hooked"], runs["plain"]
    # import mitld_lp alone: nothing of NumPy, SciPy or dataclasses, and no hook until
    # the program asks for it (install); then it waits
    assert hooked["plain_import"] == [] and hooked["unasked"] is False
    assert plain["unasked"] is False and plain["waiting"] is False
    assert hooked["waiting"] is True
    # neither module seen: csgraph, which this small product's walks do not need, and
    # SciPy's copy of NumPy's namespace, whose layer the route leaves unrun
    # (mitld_lp.own_imports.LayerLater), both awaited
    assert hooked["left"] == ["scipy._lib.array_api_compat.numpy", "scipy.sparse.csgraph"]
    assert hooked["loaded"] == []
    # as imported (mitld_lp.own_imports): SciPy's layer, imported by the package's
    # modules, leaves them too, without the program's hook
    assert runs["default"]["loaded"] == [] and runs["default"]["waiting"] is False
    # with the imports as Python makes them, SciPy's copy imports them: the probe sees them
    assert set(plain["loaded"]) >= {"numpy.f2py", "numpy.testing", "numpy.polynomial"}


def test_scipys_copy_of_numpy_is_the_same_namespace(runs: dict[str, dict]) -> None:
    plain = runs["plain"]
    for cut in (runs["hooked"], runs["default"]):
        assert cut["copy_all"] == plain["copy_all"]
        assert set(cut["copy_dir"]) == set(plain["copy_dir"])
        assert cut["same"] == plain["same"] == [True] * 4  # NumPy's own objects, asked later
        assert cut["numpy_all"] == plain["numpy_all"]  # NumPy's __all__ put back


def test_only_the_packages_dataclasses_are_made_without_exec(runs: dict[str, dict]) -> None:
    hooked, default, plain = runs["hooked"], runs["default"], runs["plain"]
    # the program's own class: the stdlib's compiled methods, hooked or not
    assert (hooked["mine"] == default["mine"] == plain["mine"]
            == ["<string>", "<string>", "Mine(x=1)", True, True])
    if sys.version_info[:2] in ((3, 11), (3, 12)):  # startup.DATACLASS_PYTHONS
        assert hooked["ours"] == default["ours"] == [False, plain["ours"][1]]
        assert plain["ours"][0] is True


def test_the_answer_is_the_same_to_the_bit_and_storms(runs: dict[str, dict],
                                                       tmp_path: Path) -> None:
    import stormpy

    hooked, plain = runs["hooked"], runs["plain"]
    assert hooked["answer"] == runs["default"]["answer"] == plain["answer"]
    lower, upper, certified = (float.fromhex(hooked["answer"][0]),
                               float.fromhex(hooked["answer"][1]), hooked["answer"][2])
    assert certified and lower <= upper
    path = tmp_path / "robot.prism"
    path.write_text(PRISM, encoding="utf-8")
    program = stormpy.parse_prism_program(str(path))
    prop = stormpy.parse_properties('Pmax=? [F "goal"]', program)[0]
    model = stormpy.build_model(program, [prop])
    result = stormpy.model_checking(model, prop)
    storm = result.get_value_vector()[model.initial_states[0]]
    # Storm's default value iteration stops at a relative 1e-6
    assert storm == pytest.approx(VALUE, abs=1e-5)  # Storm against the hand calculation
    assert lower - 1e-5 <= storm <= upper + 1e-5
    assert lower - 1e-12 <= VALUE <= upper + 1e-12

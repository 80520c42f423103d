"""A program importing the package (:mod:`mitld_lp.own_imports`): while the package's
modules import, the collector is held and the package's dataclass makers are in place;
after, the caller's collector state and the stdlib's makers are back, nothing frozen;
the PRISM route's imports leave NumPy's extra submodules unloaded.  Each in a fresh
interpreter (what is imported is the point)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _run(code: str, *args: str, plain: bool = False) -> dict:
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONDONTWRITEBYTECODE", "MITLD_LP_PLAIN_IMPORTS")}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    if plain:
        env["MITLD_LP_PLAIN_IMPORTS"] = "1"
    done = subprocess.run([sys.executable, "-c", code, *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


#: A finder after the package's that notes the collector's state when SciPy (imported by
#: the MDP's module body) and NumPy are looked for, then the route's imports;
#: argv[1]: the caller's collector, "on" or "off".
GC_PROBE = r"""
import gc, json, sys
if sys.argv[1] == "off":
    gc.disable()
seen = {}
class Spy:
    def find_spec(self, name, path=None, target=None):
        if name in ("scipy", "numpy"):
            seen.setdefault(name, gc.isenabled())
        return None
import mitld_lp
sys.meta_path.insert(0, Spy())
from mitld_lp import load_model, synthesize
import dataclasses
print(json.dumps(dict(seen=seen, enabled=gc.isenabled(), frozen=gc.get_freeze_count(),
                      repr_fn=dataclasses._repr_fn.__module__,
                      create_fn=dataclasses._create_fn.__module__)))
"""


@pytest.mark.parametrize("caller", ["on", "off"])
def test_the_collector_is_held_while_the_package_imports_and_put_back(caller: str) -> None:
    got = _run(GC_PROBE, caller)
    # during the package's module bodies (the MDP's imports SciPy, the model's NumPy)
    assert got["seen"] == {"scipy": False, "numpy": False}
    # after: as the caller had it, and none of the caller's objects frozen
    assert got["enabled"] is (caller == "on")
    assert got["frozen"] == 0
    # the stdlib's dataclass makers are back
    assert got["repr_fn"] == "dataclasses" and got["create_fn"] == "dataclasses"


def test_plain_imports_leave_the_collector_running() -> None:
    """The probe can see the difference: with ``MITLD_LP_PLAIN_IMPORTS=1`` the imports
    run with the collector on."""
    got = _run(GC_PROBE, "on", plain=True)
    assert got["seen"] == {"scipy": True, "numpy": True} and got["enabled"] is True


#: The package's class and the program's class made after the package's imports (the
#: makers back), and one the program makes in a module named as the package's own is
#: not; argv: nothing.
CLASSES = r"""
import json
from mitld_lp import load_model, synthesize
from mitld_lp.logic.syntax import Prop, Until
from dataclasses import dataclass
@dataclass(frozen=True)
class Mine:
    x: int
    y: str = "a"
def where(cls):
    return [cls.__eq__.__code__.co_filename.rsplit("/", 1)[-1],
            cls.__setattr__.__code__.co_filename.rsplit("/", 1)[-1]]
p = Prop("goal")
try:
    p.name = "other"
    refused = None
except Exception as exc:
    refused = type(exc).__name__
print(json.dumps(dict(ours=where(Prop), mine=where(Mine), repr=[repr(p), repr(Mine(1))],
                      eq=[p == Prop("goal"), p == Prop("other"), Mine(1) == Mine(1)],
                      hash=[hash(p) == hash(Prop("goal")), hash(Mine(2)) == hash((2, "a"))],
                      refused=refused)))
"""


@pytest.mark.skipif(sys.version_info[:2] not in ((3, 11), (3, 12)),
                    reason="dataclass_closures.DATACLASS_PYTHONS")
def test_only_the_packages_classes_get_the_closures() -> None:
    got = _run(CLASSES)
    assert got["ours"] == ["dataclass_closures.py", "dataclass_closures.py"]
    assert got["mine"] == ["<string>", "<string>"]  # the stdlib's, compiled
    assert got["repr"][1] == "Mine(x=1, y='a')"
    assert got["eq"] == [True, False, True] and got["hash"] == [True, True]
    assert got["refused"] == "FrozenInstanceError"
    plain = _run(CLASSES, plain=True)
    assert plain["ours"] == ["<string>", "<string>"]
    assert {k: plain[k] for k in ("repr", "eq", "hash", "refused")} == {
        k: got[k] for k in ("repr", "eq", "hash", "refused")}


#: The window's own bookkeeping under a failing package import, and an import the
#: program makes of a module the package imports in its functions (numba's stand-in
#: here: csgraph) is not the package's: the collector stays on for it.
NESTED = r"""
import gc, json, sys
seen = {}
class Spy:
    def find_spec(self, name, path=None, target=None):
        if name in ("scipy.sparse.csgraph", "scipy.sparse.csgraph._laplacian"):
            seen.setdefault(name, gc.isenabled())
        return None
import mitld_lp
from mitld_lp import own_imports
sys.meta_path.insert(1, Spy())
try:
    import mitld_lp.no_such_module
except ImportError:
    pass
import scipy.sparse.csgraph
print(json.dumps(dict(inside=own_imports.inside(), enabled=gc.isenabled(), seen=seen)))
"""


def test_the_programs_own_import_of_a_later_module_is_left_alone() -> None:
    got = _run(NESTED)
    assert got["inside"] is False and got["enabled"] is True
    assert got["seen"] == {"scipy.sparse.csgraph": True, "scipy.sparse.csgraph._laplacian": True}


#: The package's code importing csgraph (a module of :data:`own_imports.LATER`, inside a
#: function): the collector is held during it.
LATER = r"""
import gc, json, sys
seen = {}
class Spy:
    def find_spec(self, name, path=None, target=None):
        if name == "scipy.sparse.csgraph._laplacian":
            seen.setdefault(name, gc.isenabled())
        return None
import scipy.sparse
from mitld_lp.util import traversal  # the package's first import: the finder in place
from mitld_lp import own_imports
sys.meta_path.insert(1, Spy())
assert "scipy.sparse.csgraph" not in sys.modules
# code whose module is the package's (as mitld_lp.util.traversal's function runs it)
exec(compile("import scipy.sparse.csgraph", "<pkg>", "exec"), {"__name__": "mitld_lp.fake"})
print(json.dumps(dict(seen=seen, enabled=gc.isenabled(), inside=own_imports.inside())))
"""


def test_the_packages_import_of_a_later_module_holds_the_collector() -> None:
    got = _run(LATER)
    assert got["seen"] == {"scipy.sparse.csgraph._laplacian": False}
    assert got["enabled"] is True and got["inside"] is False


#: The PRISM route's imports (``load_model``, ``synthesize``: SciPy's sparse matrices
#: come with them), then which of NumPy's extra submodules are loaded, and SciPy's copy
#: of NumPy's namespace asked for one of them.
EXTRAS = r"""
import json, sys
from mitld_lp import load_model, synthesize
import scipy.sparse
loaded = sorted(m for m in ("numpy.f2py", "numpy.testing", "numpy.polynomial", "numpy.ma")
                if m in sys.modules)
import numpy
from scipy._lib.array_api_compat import numpy as copy
print(json.dumps(dict(loaded=loaded, handed=copy.testing is numpy.testing,
                      listed="testing" in copy.__all__)))
"""


def test_the_prism_routes_imports_leave_numpys_extras_unloaded() -> None:
    got = _run(EXTRAS)
    assert got["loaded"] == []
    assert got["handed"] is True and got["listed"] is True  # handed over when asked
    plain = _run(EXTRAS, plain=True)
    assert set(plain["loaded"]) >= {"numpy.f2py", "numpy.testing", "numpy.polynomial"}
    assert plain["handed"] is True and plain["listed"] is True

"""A PRISM property's route leaves SciPy's array-API layer, lark's cache modules and
``zipfile`` out.

A fresh program imports the package and answers a PRISM property (its spec parsed by the
package's formula parser, loaded from the stored LALR tables).  After the answer,
``sys.modules`` holds neither ``getpass`` (lark's cache owner, with ``termios``) nor
``zipfile`` nor SciPy's ``array_api_compat``/``array_api_extra``, and SciPy's array-API
layer is a stand-in whose body has not run (``mitld_lp.own_imports.LayerLater``).  The
answer is checked against Storm's sound check of the same PRISM file (an independent
route).  Then, in the same process: lark building a parser from a grammar with its cache
(the grammar's SHA-256 through ``hashlib``, the cache's folder through ``tempfile``, its
owner through ``getpass``) gets the real modules; a zip archive read through the file
rules is checked by the real ``zipfile``; SciPy's ``_contains_nan`` (which asks the
layer for the array's namespace) runs the layer's body in the same module, after which
``scipy._lib._util`` holds SciPy's own functions and ``scipy.stats`` imports as usual.
"""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

PRISM = """mdp
module walk
  x : [0..4] init 1;
  // x = 0: lost; x = 4: reached
  [a] x>0 & x<4 -> 0.5:(x'=x+1) + 0.5:(x'=x-1);
  [b] x>0 & x<4 -> 0.25:(x'=x+1) + 0.75:(x'=x);
  [] x=0 | x=4 -> true;
endmodule
"""

PROBE = r"""
import json, sys, types
from mitld_lp import load_model, synthesize
r = synthesize(load_model(sys.argv[1]))
out = dict(lower=r.lower, upper=r.upper, certified=r.certified,
           left_out=sorted(m for m in ("getpass", "termios", "zipfile", "regex",
                                       "scipy._lib.array_api_compat",
                                       "scipy._lib.array_api_extra") if m in sys.modules),
           layer=type(sys.modules.get("scipy._lib._array_api")).__name__)
# another route: SciPy's array-API layer on its first use, through scipy._lib._util
import numpy as np
layer = sys.modules["scipy._lib._array_api"]
import scipy._lib._util as util
out["nan"] = [bool(util._contains_nan(np.array([1.0, np.nan]))),
              bool(util._contains_nan(np.array([1.0, 2.0])))]
out["layer_after"] = [type(layer) is types.ModuleType,
                      sys.modules["scipy._lib._array_api"] is layer,
                      util.array_namespace is layer.array_namespace,
                      util.xp_size is layer.xp_size, util.Array is layer.Array]
import scipy.stats
out["cdf"] = float(scipy.stats.norm.cdf(0.0))
# another route: lark building a parser from a grammar, with its cache
import lark.lark, lark.load_grammar
from lark import Lark
g = Lark("start: W\nW: /[a-z]+/\n", parser="lalr", cache=sys.argv[2])
out["parsed"] = str(g.parse("abc").children[0])
import getpass, hashlib, tempfile
out["real"] = [type(m) is types.ModuleType for m in (getpass, hashlib, tempfile)]
out["same"] = [lark.load_grammar.hashlib.sha256 is hashlib.sha256,
               lark.lark.tempfile.gettempdir is tempfile.gettempdir,
               lark.lark.getpass.getuser is getpass.getuser]
# the file rules reading a zip archive: the real zipfile refuses an over-large member
import io, zipfile
from mitld_lp.files.rules import InputFileError, check_zip
buf = io.BytesIO()
with zipfile.ZipFile(buf, "w") as z:
    z.writestr("a.txt", b"x" * 1000)
buf.seek(0)
try:
    check_zip(buf, 999, "the archive")
    out["zip"] = "accepted"
except InputFileError:
    out["zip"] = "refused"
buf.seek(0)
check_zip(buf, 1000, "the archive")
out["zip_ok"] = buf.tell() == 0
print(json.dumps(out))
"""


def _storm(prism: Path) -> float:
    pytest.importorskip("stormpy")
    from storm_exact import storm_sound

    return storm_sound(prism, 'Pmin=? [F x=4]')


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, float]:
    pytest.importorskip("stormpy")
    work = tmp_path_factory.mktemp("walk")
    prism = work / "walk.prism"
    prism.write_text(PRISM, encoding="utf-8")
    model = work / "walk.toml"
    model.write_text('name = "walk"\nspec = "F reached"\nobjective = "min"\n\n[prism]\n'
                     'file = "walk.prism"\n\n[labels]\nreached = "x = 4"\n', encoding="utf-8")
    from fresh_child import run_fresh

    return run_fresh(PROBE, str(model), str(work / "lark.cache")), _storm(prism)


def test_the_prism_route_leaves_larks_cache_modules_and_zipfile_out(run) -> None:
    got, _ = run
    assert got["left_out"] == []


def test_the_answer_is_storms(run) -> None:
    got, storm = run
    assert got["certified"] is True
    # minimising: a always risks x = 0 (from 1: 1/2 down at once), b never loses; the
    # minimum from x = 1 under a is the gambler's ruin from 1 of 4 with p = 1/2: 1/4
    assert storm == pytest.approx(0.25, abs=2e-9)
    assert got["lower"] - 2e-9 <= storm <= got["upper"] + 2e-9


def test_lark_and_the_file_rules_get_the_real_modules_on_first_use(run) -> None:
    got, _ = run
    assert got["parsed"] == "abc"
    assert got["real"] == [True, True, True]
    assert got["same"] == [True, True, True]
    assert got["zip"] == "refused"  # 1,000 bytes inflated against a limit of 999
    assert got["zip_ok"] is True


def test_scipys_array_api_layer_is_left_unrun_and_is_scipys_on_first_use(run) -> None:
    got, _ = run
    assert got["layer"] == "LayerLater"
    # [1, nan] holds a NaN, [1, 2] does not
    assert got["nan"] == [True, False]
    assert got["layer_after"] == [True, True, True, True, True]
    assert got["cdf"] == 0.5  # the standard normal's distribution at its median

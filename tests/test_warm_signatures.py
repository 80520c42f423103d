"""``mitld-lp warm``'s list of kernel signatures (mitld_lp.util.warm_kernels) does not rot:
every (kernel, argument types) pair small solves of several shapes call, with the
compiled gates forced on, is listed; every listed signature names a kernel of that many
arguments and makes arguments of exactly its type; and ``Kernel.compile_for`` writes the
loader's cache file without running the kernel, which a later process links."""

from __future__ import annotations

import inspect
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")

from mitld_lp.util import kernel_loader, warm_kernels  # noqa: E402
from mitld_lp.util.kernel_types import sample_args, type_key  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def test_encode_writes_each_argument_type_by_hand():
    ro = np.zeros((2, 4), dtype=np.int32)[:, ::2]
    ro.setflags(write=False)
    args = (np.zeros(3), ro, np.zeros((2, 2), dtype=np.bool_, order="F"), 1, 1.0, True,
            np.int64(3), np.zeros(0, dtype=np.uint8))
    text = warm_kernels.encode(type_key(args))
    assert text == "f8/1C i4/2A/ro b1/2F int float bool np.i8 u1/1C"
    assert warm_kernels.decode(text) == type_key(args)
    unaligned = np.frombuffer(bytearray(17), dtype=np.uint8)[1:].view(np.float64)
    assert warm_kernels.encode(type_key((unaligned,))) == "f8/1C/un"


@pytest.mark.parametrize("bad", ["f8/1X", "f8/1C/rw", "list", "f8/C1", "np.zz"])
def test_decode_names_the_word_it_cannot_read(bad):
    with pytest.raises((ValueError, TypeError), match="not an argument type|data type"):
        warm_kernels.decode(f"int {bad}")


def test_every_listed_signature_is_a_kernel_of_that_many_arguments():
    listed = list(warm_kernels.signatures())
    assert len(listed) >= 40  # the analysis', the iteration's, the certificate's, ...
    for module, name, key in listed:
        kernel = getattr(__import__(module, fromlist=[name]), name)
        assert isinstance(kernel, kernel_loader.Kernel), (module, name)
        assert kernel.cacheable(), (module, name)
        params = inspect.signature(kernel.py_func).parameters.values()
        required = sum(p.default is inspect.Parameter.empty for p in params)
        assert required <= len(key) <= len(params), (module, name, len(key))
        args = sample_args(key)  # arguments of exactly the listed type
        assert type_key(args) == key
        assert warm_kernels.decode(warm_kernels.encode(key)) == key


TINY_PRISM = """\
mdp
module m
  x : [0..3] init 0;
  [a] x<3 -> 0.5:(x'=x+1) + 0.5:(x'=x);
  [b] x<3 -> 0.9:(x'=min(x+2,3)) + 0.1:(x'=0);
  [] x=3 -> true;
endmodule
label "goal" = x=3;
"""


# Small solves, numba disabled (the kernels run as Python: nothing compiled), every gate
# that asks whether a kernel is cached or its load paid answering yes, and the sizes the
# gates send to compiled kernels lowered to 1: the (kernel, types) pairs called.
RECORD_CHILD = r"""
import json, sys
import dataclasses
from types import MappingProxyType
from mitld_lp.util import warm_kernels
seen = warm_kernels.record(force_gates=True)
import importlib
LOWERED = {
    "mitld_lp.solvers.walks": ["COMPILED_MIN_ENTRIES", "COMPILED_LOADED_MIN_ENTRIES"],
    "mitld_lp.solvers.analysis_gates": ["WARM_MIN_ENTRIES", "PAID_MIN_ENTRIES",
                                        "DENSE_ENTRIES"],
    "mitld_lp.solvers.certify_compiled": ["COMPILED_CHECK_MIN_ROWS", "WARM_LOAD_MIN_ENTRIES",
                                          "CYCLING_MIN_STATES"],
    "mitld_lp.solvers.certify_chain": ["CHAIN_KERNEL_MIN_LEVELS"],
    "mitld_lp.solvers.quotient": ["LIFT_KERNEL_MIN_STATES"],
    "mitld_lp.solvers.quotient_rows": ["COMPILED_MIN_ENTRIES"],
    "mitld_lp.solvers.greedy_block": ["KERNEL_MIN_CHOICES"],
    "mitld_lp.solvers.lp_blocks": ["GREEDY_MIN_CHOICES"],
    "mitld_lp.solvers.eliminate": ["MIN_PRODUCT_ENTRIES", "MIN_BLOCK_ENTRIES", "MIN_ENTRIES"],
    "mitld_lp.solvers.topological": ["LEVEL_KERNEL_MIN_ENTRIES", "LEVEL_KERNEL_MIN_LEVELS"],
    "mitld_lp.solvers.chain_levels": ["WALK_MIN_STATES", "OFFER_MIN_LEVELS"],
    "mitld_lp.solvers.level_gate": ["DEEP_LEVELS"],
    "mitld_lp.sensing.rows": ["COMPILED_MIN_STATES", "COMPILED_MIN_ESTIMATE"],
    "mitld_lp.product.table_levels": ["COMPILED_MIN_STATES", "COLD_MIN_STATES"],
    "mitld_lp.worlds.prism_build": ["OWN_FROM_STATES"],
    "mitld_lp.routes.horizon": ["CLAIM_FROM"],
}
for name, attrs in LOWERED.items():
    module = importlib.import_module(name)
    for attr in attrs:
        if not hasattr(module, attr):
            raise SystemExit(f"{name}.{attr}: no such gate any more (update the test)")
        setattr(module, attr, 1)
from pathlib import Path
from mitld_lp import load_model, synthesize
from mitld_lp.sensing import Sensor
models = ROOT / "models"
bus = load_model(models / "bus_grid.toml")
synthesize(bus)  # the bundled case
synthesize(load_model(models / "corridor.toml"))  # a PRISM world whose events change it
for spec in ("F goal", "F[0,6] goal", "G !goal"):  # reach, step-bounded, a minimum's
    Path("tiny.toml").write_text(f'name = "tiny"\nspec = "{spec}"\n'
                                 '[prism]\nfile = "tiny.prism"\n')
    synthesize(load_model(Path("tiny.toml")))  # a PRISM world the own explorer builds
synthesize(load_model(models / "bus_puddle.toml"))  # a safety part: a minimum
synthesize(dataclasses.replace(bus, epsilon=0.05, sensors=MappingProxyType(
    {"b1": Sensor(0.5)})))  # the sensed route
print(json.dumps(sorted(seen)))
"""


def test_every_kernel_small_solves_call_is_listed(tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(tmp_path / "cache"),
               NUMBA_DISABLE_JIT="1", MITLD_PRISM_BUILDER="own")
    (tmp_path / "tiny.prism").write_text(TINY_PRISM, encoding="ascii")
    code = RECORD_CHILD.replace("ROOT /", f"__import__('pathlib').Path({str(ROOT)!r}) /")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, cwd=str(tmp_path), timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    called = {tuple(c) for c in json.loads(done.stdout.strip().splitlines()[-1])}
    reached = {m.rsplit(".", 1)[1] for m, _, _ in called}  # the gates forced on:
    assert reached >= {"kernels", "group_kernels", "compiled_graph", "certify_kernels",
                       "certify_repair_kernels", "level_kernels", "quotient_kernels",
                       "greedy_kernels", "prism_kernels", "horizon_kernels"}, reached
    listed = {(m, n, warm_kernels.encode(k)) for m, n, k in warm_kernels.signatures()}
    assert not {c for c in called if c[2] == "?"}, "a call the loader cannot key"
    assert called - listed == set(), "not in warm_kernels.SIGNATURES (add them)"


WARM_CHILD = r"""
import json, sys
from mitld_lp.solvers import lift_kernels
from mitld_lp.util import kernel_loader, warm_kernels
from mitld_lp.util.kernel_types import sample_args
[(_, _, key)] = [s for s in warm_kernels.signatures()
                 if s[:2] == ("mitld_lp.solvers.lift_kernels", "first_staying_kernel")]
kernel = lift_kernels.first_staying_kernel
before = kernel_loader.cached(lift_kernels.__file__, "first_staying_kernel")
first = kernel.compile_for(sample_args(key))
print(json.dumps({"before": before, "first": first,
                  "again": kernel.compile_for(sample_args(key)),
                  "after": kernel_loader.cached(lift_kernels.__file__,
                                                "first_staying_kernel")}))
"""

LINK_CHILD = r"""
import json, sys
import numpy as np, scipy.sparse as sp
from mitld_lp.solvers.lift_kernels import first_staying
from mitld_lp.util import kernel_loader
m = sp.csr_array((np.array([1.0, 0.5, 0.0, 1.0]), np.array([1, 0, 1, 1], dtype=np.int32),
                  np.array([0, 1, 3, 4], dtype=np.int32)), shape=(3, 2))
got = first_staying(np.array([0, 2, 3]), m, np.array([True, False]), np.array([0]))
print(json.dumps({"got": np.asarray(got).tolist(), "loaded": kernel_loader.loaded_count(),
                  "numba": "numba" in sys.modules}))
"""


def test_compile_for_writes_a_file_a_later_process_links(tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(tmp_path / "cache"))

    def child(code: str) -> dict:
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              env=env, cwd=str(tmp_path), timeout=600)
        assert done.returncode == 0, done.stderr[-3000:]
        return json.loads(done.stdout.strip().splitlines()[-1])

    assert child(WARM_CHILD) == {"before": False, "first": True, "again": False,
                                 "after": True}
    linked = child(LINK_CHILD)
    # state 0's choices are rows 0 and 1: row 0 goes to state 1 (outside); row 1 to
    # state 0 (inside) and to state 1 with a stored zero (no edge): row 1 is the first
    # that stays
    assert linked == {"got": [1], "loaded": 1, "numba": False}


@pytest.mark.parametrize(("done", "said"), [
    ((3, 43, 1.25), "compiled 3 of the solve's 43 kernel signatures in 1.2 s of CPU"),
    ((0, 43, 0.01), "the solve's 43 kernel signatures were compiled already"),
    ((0, 0, 0.0), "numba is not installed: the solve runs its NumPy routes"),
])
def test_warm_says_how_many_signatures_it_compiled(monkeypatch, capsys, done, said):
    pytest.importorskip("stormpy")
    from mitld_lp.cli import main
    from mitld_lp.solvers import lift_kernels, topo_chain
    from mitld_lp.worlds import prism_explore

    monkeypatch.setattr(prism_explore, "kernel_ready", lambda: True)
    monkeypatch.setattr(prism_explore, "compile_kernels", lambda *_: False)
    monkeypatch.setattr(topo_chain, "compile_kernels", lambda: False)
    monkeypatch.setattr(lift_kernels, "warm_up", lambda: None)
    monkeypatch.setattr(warm_kernels, "compile_all", lambda *_: done)
    assert main(["warm"]) == 0
    out = capsys.readouterr()
    assert said in out.out
    assert "the solve's kernels: compiling those not cached" in out.err
    assert main(["warm", "-q"]) == 0
    assert capsys.readouterr().err == ""

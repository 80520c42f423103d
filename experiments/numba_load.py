"""What a process pays to load numba and the compiled kernels, part by part.

Each round is a fresh process (``--rounds``, default 5) that imports NumPy, SciPy's
sparse matrices and ``scipy.linalg`` (loaded by every solve of a product large enough to
sweep with the kernel), then times in CPU seconds: ``import numba``; the typing
context's registries; the CPU target's registries (numba refreshes them before loading
any kernel from its disk cache, :func:`numba.core.caching` ``load_overload``); the
first call of a graph kernel (:func:`mitld_lp.solvers.compiled_graph.end_components_among`,
the first kernel the analysis of a large product asks for; its end components of a
two-state block printed beside); the first call of the block kernel
(:func:`mitld_lp.solvers.kernels.compiled_sweeps`, its load from the cache and its run
on the same block: its bracket of 1/2 is printed beside); and the first call of one
level kernel.  The kernels must be in the disk cache (run the script twice after a
change: the first run compiles them).  Prints the median and least of each part::

    python experiments/numba_load.py

Two sets of rounds take turns: ``whole`` (:data:`mitld_lp.util.numba_narrow.ENABLED`
set to False: numba's own load, as a process that asked for a graph kernel first had
before every compiled module put the narrow load in place) and ``narrow`` (what every
compiled module does since: the target's registries are not refreshed, and the first
call loads the kernel with numba's runtime only; since the numba-gate branch the typing
context is not refreshed either, and numba is imported by
:func:`mitld_lp.util.numba_narrow.import_numba`, without PyYAML).  The answers must
be the same to the bit in both; which of PyYAML, cffi and pycparser each load left in
the process is printed.  ``--compare DIR`` also runs the narrow load of another
checkout's ``mitld_lp`` (a ``git archive`` of an older commit), taking turns, and the
kernel loader's rounds of both checkouts: the other's, this one's with llvmlite's linker
(``loader llvm``: ``kernel_loader.LINKER = "llvm"``) and this one's own (``loader``:
:mod:`mitld_lp.util.elf_link`).  ``--steps`` instead prints the resident memory
(``RssAnon``, ``RssFile``) and CPU of each step of the loader's set-up and of one kernel's
link, with llvmlite's linker and with ``elf_link``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

CHILD = r"""
import json, time
c = time.process_time
def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20
import numpy as np, scipy.sparse as sp, scipy.linalg  # noqa: F401
t = [c()]
m = [rss()]
def mark():
    t.append(c())
    m.append(rss())
try:  # the loader (kernel-loader branch): on in the loader's rounds only
    from mitld_lp.util import kernel_loader
    kernel_loader.ENABLED = LOADER
    kernel_loader.LINKER = LINKER  # "elf" (loader-floor branch) or "llvm" (llvmlite's MCJIT)
except ImportError:  # an older checkout
    pass
if LOADER:  # numba is never imported: no part of its load happens
    for _ in range(5):
        mark()
else:
    if NARROW:
        from mitld_lp.util import numba_narrow
        getattr(numba_narrow, "import_numba", lambda: __import__("numba"))()  # without PyYAML
    else:
        import numba  # noqa: F401
    mark()
    from numba.core.registry import cpu_target
    from numba.core.runtime import rtsys
    if NARROW:
        assert numba_narrow.install()
        mark()  # the typing registries: not refreshed by the narrow load
        try:  # what the narrow load does at the first kernel's call, made a part of its own
            from mitld_lp.util import nrt_cache
            nrt_cache.initialize(cpu_target.target_context)
        except ImportError:  # an older checkout: numba compiles its runtime
            rtsys.initialize(cpu_target.target_context)
        mark()
        mark()  # the rest of the target's registries: not refreshed by the narrow load
    else:
        from mitld_lp.util import numba_narrow
        numba_narrow.ENABLED = False  # every compiled module would put it in place
        cpu_target.typing_context.refresh()
        mark()
        rtsys.initialize(cpu_target.target_context)  # the first step of the refresh
        mark()
        cpu_target.target_context.refresh()
        mark()
    if not (NARROW and hasattr(numba_narrow, "_rebuild_env")):
        # the module of the array helpers' environments, which the first call of a kernel
        # imports (numba's load and older checkouts; since numba-load the narrow load does not)
        import numba.np.arrayobj  # noqa: F401
    mark()
inner = sp.csr_array(np.array([[0.0, 0.5], [0.5, 0.0]]))
from mitld_lp.solvers import compiled_graph
alive, allowed, label = compiled_graph.end_components_among(
    inner.indptr, inner.indices, inner.data > 0, np.array([0, 1, 2]), np.arange(2))
mark()
from mitld_lp.solvers import kernels
prep = kernels.Prepared(inner, np.array([0, 1, 2]))
local = np.column_stack([np.zeros(2), np.ones(2)])
kernels.compiled_sweeps(prep, np.full((2, 2), 0.25), local, 1e-12, 1000)
mark()
from mitld_lp.solvers import level_kernels
x = np.zeros((2, 1))
diag = np.zeros(2)
diag.flags.writeable = False  # the types the solver passes: no signature of its own
level_kernels.chain_solve(np.arange(2), inner.indptr, inner.indices, inner.data, diag,
                          np.ones((2, 1)), x)  # SciPy's int32 index, as chain_levels passes
mark()
parts = [b - a for a, b in zip(t, t[1:])]
import sys
print(json.dumps({"parts": parts, "rss": [b - a for a, b in zip(m, m[1:])],
                  "numba": "numba" in sys.modules,
                  "modules": [m for m in ("yaml", "cffi", "pycparser", "numba.np.arrayobj",
                                          "llvmlite.binding")
                              if m in sys.modules],
                  "answer": [float(local[0, 0]).hex(), float(local[0, 1]).hex()],
                  "components": [alive.tolist(), label.tolist()]}))
"""

NAMES = ("import numba", "typing registries", "numba's runtime (NRT)",
         "target registries (rest)", "numba.np.arrayobj (envs)", "graph kernel, first call",
         "block kernel, first call", "a level kernel, first call")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=5, help="fresh processes (default 5)")
    ap.add_argument("--quick", action="store_true",
                    help="one round (it prints only: no file is written either way)")
    ap.add_argument("--compare", type=Path, default=None, metavar="DIR",
                    help="also the narrow load of this checkout's mitld_lp (before/after)")
    ap.add_argument("--steps", action="store_true",
                    help="instead: RssAnon / RssFile and CPU at each step of the loader's "
                         "set-up and of one kernel's link, llvmlite's MCJIT then elf_link")
    args = ap.parse_args(argv)
    if args.quick:
        args.rounds = 1
    if args.compare is not None and not (args.compare / "mitld_lp").is_dir():
        ap.error(f"--compare {args.compare}: no mitld_lp package in that directory")
    if args.steps:
        return _steps(args.rounds)
    modes = {"whole": (False, None), "narrow": (True, None), "loader": ("elf", None)}
    if args.compare is not None:
        modes = {"whole": (False, None), "base narrow": (True, args.compare.resolve()),
                 "narrow": (True, None), "base loader": ("elf", args.compare.resolve()),
                 "loader llvm": ("llvm", None), "loader": ("elf", None)}
    runs: dict[str, list[dict]] = {m: [] for m in modes}
    for _ in range(args.rounds):  # the loads taking turns
        for mode, (narrow, code) in modes.items():
            env = dict(os.environ)  # the checkout's package first; run from elsewhere
            env["PYTHONPATH"] = os.pathsep.join([str(code or ROOT), *filter(None, [
                env.get("PYTHONPATH")])])
            linker = narrow if narrow in ("elf", "llvm") else "elf"
            head = (f"NARROW = {bool(narrow)}\nLOADER = {linker == narrow}\n"
                    f"LINKER = {linker!r}\n")
            done = subprocess.run([sys.executable, "-c", head + CHILD],
                                  text=True, capture_output=True, env=env,
                                  cwd=tempfile.gettempdir())
            if done.returncode:
                sys.exit(f"the child failed:\n{done.stderr}")
            runs[mode].append(json.loads(done.stdout.strip().splitlines()[-1]))
    answers = {tuple(r["answer"]) for rs in runs.values() for r in rs}
    if len(answers) != 1:
        sys.exit(f"the loads' brackets differ: {answers}")
    comps = {json.dumps(r["components"]) for rs in runs.values() for r in rs}
    if len(comps) != 1:
        sys.exit(f"the loads' end components differ: {comps}")
    for mode, rs in runs.items():
        print(f"{mode} load: of PyYAML, cffi, pycparser, numba.np.arrayobj loaded: "
              f"{sorted({m for r in rs for m in r['modules']})}; numba imported: "
              f"{sorted({r.get('numba') for r in rs}, key=str)}")
    low, high = (float.fromhex(x) for x in answers.pop())
    print(f"block kernel's bracket on the two-state block, every load: [{low:.12f}, "
          f"{high:.12f}] (exact 1/2: x = 1/4 + x/2)")
    print(f"graph kernel's end components of the two-state block, every load (alive, "
          f"label): {comps.pop()} (one end component of both states)")
    print(f"{'part':<28}" + "".join(f" {m + ': median s':>22} {'least s':>8} {'MB':>6}"
                                    for m in runs))
    for i, name in enumerate((*NAMES, "total")):
        cells = []
        for rs in runs.values():
            xs = [sum(r["parts"]) if name == "total" else r["parts"][i] for r in rs]
            mb = [sum(r["rss"]) if name == "total" else r["rss"][i] for r in rs]
            cells.append(f" {statistics.median(xs):22.3f} {min(xs):8.3f} "
                         f"{statistics.median(mb):6.1f}")
        print(f"{name:<28}" + "".join(cells))
    print("MB: the process's resident memory gained in the part (median)")
    _sizes()


STEPS_CHILD = r"""
import json, sys, time
def status():
    with open("/proc/self/status") as f:
        d = dict(line.split(":", 1) for line in f)
    return [int(d[k].split()[0]) / 1024 for k in ("RssAnon", "RssFile")]
import numpy as np, scipy.sparse as sp, scipy.linalg  # noqa: F401
from mitld_lp.util import elf_link, elf_runtime, kernel_files, kernel_loader as kl
from mitld_lp.solvers import compiled_graph
marks = []
def mark(name):
    marks.append((name, time.process_time(), *status()))
mark("start")
(helperlib, nrt, dynfunc), numba_id = elf_runtime.load_extensions(kl._EXTENSIONS)
mark("numba's 3 extension modules")
elf_runtime.prime_unpickle(helperlib.c_helpers["unpickle"])
mark("unpickle primed")
symbols = elf_runtime.explicit_symbols(helperlib, nrt, dynfunc)
probe = elf_runtime.probe(sys.version, numba_id)
machine = elf_runtime.read_machine(probe)
mark("symbols, remembered machine")
kernel = compiled_graph.strong_components
args = (np.array([0, 1, 2], dtype=np.int64), np.array([1, 0], dtype=np.int64), np.bool_(False))
key = kl.type_key(args)
py = kernel.py_func.__code__.co_filename
name = kernel_files.file_name(py, kernel.__qualname__, key)
data = next((d / name).read_bytes() for d in kernel_files.directories(py)
            if (d / name).is_file())
meta, obj = kernel_files.unpack(data)
mark("cache file read")
if LINKER == "llvm":
    from llvmlite import binding as ll
    mark("import llvmlite.binding")
    ll.initialize_native_target()
    ll.initialize_native_asmprinter()
    mark("initialize native target")
    triple, cpu = ll.get_process_triple(), ll.get_host_cpu_name()
    features = ll.get_host_cpu_features().flatten()
    mark("host CPU name, features")
    for s, a in symbols.items():
        ll.add_symbol(s, a)
    tm = ll.Target.from_triple(triple).create_target_machine(
        cpu=cpu, features=features, reloc="static", codemodel="jitdefault", jit=True)
    engine = ll.create_mcjit_compiler(ll.parse_assembly(""), tm)
    mark("symbols added, MCJIT engine")
    engine.add_object_file(ll.ObjectFileRef.from_data(obj))
    engine.finalize_object()
    address = lambda n: engine.get_global_value_address(n)  # noqa: E731
    mark("object added, finalized")
else:
    resolve = elf_runtime.resolver(symbols)
    linked = elf_link.link(obj, resolve)
    address = linked.symbols.get
    mark("elf_link.link")
import ctypes
envs = []
for env_name, modname, consts in meta["envs"]:
    env = dynfunc.Environment(sys.modules.get(modname, compiled_graph).__dict__)
    env.consts.extend(np.dtype(c) for c in consts)
    envs.append((env_name, env))
    ctypes.c_void_p.from_address(address(env_name)).value = id(env)
call = dynfunc.make_function(compiled_graph, "k", "", address(meta["wrapper"]),
                             dict(envs)[meta["env"]], (envs,))
mark("environments, make_function")
n, labels = call(*args)
mark("first call")
print(json.dumps({"marks": marks, "answer": [int(n), labels.tolist()],
                  "llvmlite": "llvmlite.binding" in sys.modules}))
"""


def _steps(rounds: int) -> None:
    """The loader's steps, part by part (``--steps``): medians over ``rounds``."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    for linker in ("llvm", "elf"):
        runs = []
        for _ in range(rounds):
            done = subprocess.run([sys.executable, "-c", f"LINKER = {linker!r}\n" + STEPS_CHILD],
                                  text=True, capture_output=True, env=env,
                                  cwd=tempfile.gettempdir())
            if done.returncode:
                sys.exit(f"the child failed (warm the cache first):\n{done.stderr}")
            runs.append(json.loads(done.stdout.strip().splitlines()[-1]))
        print(f"linker {linker}: strong_components of a 2-cycle -> {runs[0]['answer']} "
              f"(one component of both states); llvmlite.binding imported: "
              f"{sorted({r['llvmlite'] for r in runs})}")
        print(f"  {'step':<32} {'CPU s':>7} {'RssAnon MB':>11} {'RssFile MB':>11}")
        names = [m[0] for m in runs[0]["marks"]]
        for i in range(1, len(names)):
            d = [[r["marks"][i][j] - r["marks"][i - 1][j] for r in runs] for j in (1, 2, 3)]
            print(f"  {names[i]:<32} {statistics.median(d[0]):7.4f} "
                  f"{statistics.median(d[1]):11.1f} {statistics.median(d[2]):11.1f}")
        tot = [[r["marks"][-1][j] - r["marks"][0][j] for r in runs] for j in (1, 2, 3)]
        print(f"  {'total':<32} {statistics.median(tot[0]):7.4f} "
              f"{statistics.median(tot[1]):11.1f} {statistics.median(tot[2]):11.1f}")


def _sizes() -> None:
    """The cache files a process of this checkout loads: each kernel's machine code
    (numba's ``.nbc``; a kernel's callees are linked into it) and the runtime's."""
    cache = ROOT / "mitld_lp" / "solvers" / "__pycache__"
    files = sorted(cache.glob("*.nbc")) + sorted(cache.glob("nrt-*.bin"))
    if not files:
        print(f"no cache files under {cache} (numba's user-wide cache or NUMBA_CACHE_DIR)")
        return
    print("cache files of mitld_lp/solvers (bytes):")
    for path in files:
        print(f"  {path.stat().st_size:9d}  {path.name}")


if __name__ == "__main__":
    main()

"""Random inputs for the surfaces of laws from data, bands, sweeps, controller files and
``[python]`` worlds (issue 29), for the fuzz campaign (``experiments/fuzz.py``).

Each :func:`random_case` is one run: a command line or a few lines of Python, the files
it names written into a scratch folder first (:class:`SurfaceFiles`), and what to check
afterwards (a sweep's results file must hold each point at most once, and every line
whole but the last).  The campaign runs each case in a fresh process, so that its peak
memory can be compared with the ``--max-memory`` it was given.
"""

from __future__ import annotations

import csv
import io
import os
import random
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["SurfaceFiles", "Case", "random_case", "results_damage", "KINDS"]

KINDS = ("data file", "bands", "sweep results", "concurrent sweeps", "controller file",
         "python world")

_FAMILIES = ("geometric", "empirical", "poisson", "nbinom", "exponential", "weibull",
             "rayleigh", "halfcauchy", "nope", "")

_FIT_MODEL = """name = "fit"
spec = "D[mu] b & F(b & F[0,3] A)"
epsilon = 0.05
[grid]
size = [2, 2]
start = [0, 0]
[regions]
A = [[1, 1]]
[distributions]
mu = {{ fit = "{family}", data = "{data}" }}
"""

_TINY = """name = "tiny"
spec = "D[mu] e & F(e & F[0,{T}] A)"
epsilon = 0.05
[constants]
T = 2
[grid]
size = [2, 2]
start = [0, 0]
slip = 0.1
[regions]
A = [[1, 1]]
[distributions]
mu = { geometric = 0.5 }
"""

_SWEEP = """name = "s"
model = "tiny.toml"
[vary]
constants.T = [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]
distributions.mu.geometric = [0.2, 0.4, 0.6, 0.8]
"""
SWEEP_POINTS = 40
"""Points of the scratch sweep (10 deadlines x 4 laws): long enough for two sweeps to
overlap and for a kill to land in the middle."""

_WORLD = '''\
import math
import random


class W:
    proposition_names = frozenset({"goal"})

    def __init__(self, fault, state, seed):
        self.fault, self.at, self.rng = fault, state, random.Random(seed)
        self.ignores_events = True

    def _broken(self, s, method):
        return s == self.at and self.fault.startswith(method)

    @property
    def initial(self):
        if self.fault == "initial":
            raise RuntimeError("no start")
        return 0

    def actions(self, s):
        if self._broken(s, "actions"):
            return {"actions_empty": [], "actions_none": None, "actions_int": [1],
                    "actions_twice": ["a", "a"]}.get(self.fault) or _raise(self.fault)
        return ["a", "b"]

    def successors(self, s, a, events):
        nxt = (s + 1) % 4
        if self._broken(s, "successors"):
            p = {"successors_low": 0.99, "successors_high": 1.01,
                 "successors_nan": math.nan, "successors_neg": -0.5}.get(self.fault)
            if p is not None:
                return [(nxt, p)]
            if self.fault == "successors_empty":
                return []
            if self.fault == "successors_none":
                return None
            if self.fault == "successors_state":
                return [([nxt], 1.0)]
            _raise(self.fault)
        q = self.rng.choice((1.0, 0.5, 0.25))
        return [(nxt, q)] + ([(s, 1.0 - q)] if q < 1.0 else [])

    def propositions(self, s):
        if self._broken(s, "propositions"):
            return {"propositions_list": ["goal"], "propositions_unknown": frozenset({"x"}),
                    "propositions_none": None}.get(self.fault) or _raise(self.fault)
        return frozenset({"goal"}) if s == 3 else frozenset()


def _raise(fault):
    kind = fault.rsplit("_", 1)[-1]
    raise {"raise": ValueError("boom"), "kbd": KeyboardInterrupt(), "exit": SystemExit(0),
           "exit1": SystemExit("bye"), "memory": MemoryError(), "recursion":
           RecursionError("deep")}.get(kind, ValueError(kind))


def make(fault="none", state=1, seed=0):
    if fault == "factory_kbd":
        raise KeyboardInterrupt
    if fault == "factory_exit":
        raise SystemExit(0)
    if fault == "factory_raise":
        raise ValueError("factory")
    return W(fault, state, seed)
'''

_FAULTS = ("none", "initial", "actions_empty", "actions_none", "actions_int", "actions_twice",
           "actions_raise", "actions_kbd", "actions_exit", "actions_recursion",
           "successors_low", "successors_high", "successors_nan", "successors_neg",
           "successors_empty", "successors_none", "successors_state", "successors_raise",
           "successors_kbd", "successors_exit1", "propositions_list",
           "propositions_unknown", "propositions_none", "propositions_raise",
           "factory_kbd", "factory_exit", "factory_raise")


@dataclass(frozen=True, slots=True)
class SurfaceFiles:
    """The scratch folder of the surface campaign and the files its cases name."""

    folder: Path

    def prepare(self) -> None:
        """Write the fixed files (once; the cases write their own)."""
        f = self.folder
        f.mkdir(parents=True, exist_ok=True)
        (f / "tiny.toml").write_text(_TINY)
        (f / "s.toml").write_text(_SWEEP)
        (f / "bw.py").write_text(_WORLD)
        (f / "adir").mkdir(exist_ok=True)
        rng = random.Random(0)
        rows = [f"{rng.randint(1, 8)},{int(rng.random() < 0.2)}" for _ in range(40)]
        (f / "good.csv").write_text("time,censored\n" + "\n".join(rows) + "\n")
        for name, target in (("zero.csv", "/dev/zero"), ("urandom.csv", "/dev/urandom"),
                             ("full.csv", "/dev/full")):
            if not os.path.lexists(f / name):
                os.symlink(target, f / name)
        if not os.path.exists(f / "fifo.csv"):
            os.mkfifo(f / "fifo.csv")
        with (f / "sparse.csv").open("wb") as handle:
            handle.write(b"time\n")
            handle.truncate(50 * 10**9)  # 50 GB, no disk used
        (f / "junk.csv").write_bytes(bytes(rng.randrange(256) for _ in range(2000)))

    def fresh(self, name: str) -> Path:
        """``name`` in the folder, removed (with its lock) if it was there."""
        path = self.folder / name
        if path.is_dir() and not path.is_symlink():
            return path
        path.unlink(missing_ok=True)
        (self.folder / f".{name}.lock").unlink(missing_ok=True)
        return path


@dataclass(frozen=True)
class Case:
    """One run of the campaign.

    ``argv``: a command line for ``mitld-lp`` or, when ``python`` is set, that code is
    run instead; ``twin``: a second command started ``twin_delay`` seconds later on the
    same results file (concurrent writers); ``kill``: send this signal to the first after
    ``kill_after`` seconds; ``results``: the results file to check; ``max_memory``: the
    budget given, in bytes (None: the default)."""

    kind: str
    argv: list[str]
    python: str | None = None
    twin: list[str] | None = None
    twin_delay: float = 0.0
    kill: int | None = None
    kill_after: float = 0.0
    results: Path | None = None
    max_memory: int | None = None
    show: str = ""
    files: list[str] = field(default_factory=list)


_MEMORY = (("20M", 20 << 20), ("200M", 200 << 20), ("1G", 1 << 30))

_LOAD = """\
import sys
from mitld_lp import Controller
from mitld_lp.controllers.format import ControllerFileError
from mitld_lp.files.write import InputFileError
try:
    Controller.load({path!r})
except (ControllerFileError, InputFileError) as err:
    print(f"mitld-lp: error: {{err}}", file=sys.stderr)
    raise SystemExit(2)
"""

_SAVE = """\
from mitld_lp import load_model, synthesize
synthesize(load_model({model!r})).controller.save({path!r}, overwrite=True)
"""


def _memory(rng: random.Random) -> tuple[list[str], int | None]:
    if rng.random() < 0.2:
        return [], None
    text, size = rng.choice(_MEMORY)
    return ["--max-memory", text], size


def random_case(rng: random.Random, files: SurfaceFiles, kind: str | None = None) -> Case:
    """A random case of ``kind`` (default: any of :data:`KINDS`)."""
    f = files.folder
    kind = kind or rng.choice(KINDS)
    mem, size = _memory(rng)
    if kind == "data file":
        data = rng.choice(("good.csv", "zero.csv", "urandom.csv", "full.csv", "fifo.csv",
                           "sparse.csv", "junk.csv", "adir", "missing.csv"))
        family = rng.choice(_FAMILIES)
        model = f / "fit.toml"
        model.write_text(_FIT_MODEL.format(family=family, data=data))
        return Case(kind, ["solve", str(model), "-q", "--time-limit", "20", *mem],
                    max_memory=size, show=f"fit {family!r} to {data}")
    if kind == "bands":
        k = rng.randint(1, 10)
        spec = " & ".join(f"D[m{i}] e{i}" for i in range(k)) + " & F[0,3] A"
        laws = "\n".join(f"m{i} = {{ geometric = [0.3, 0.5] }}" for i in range(k))
        model = f / "band.toml"
        model.write_text(f'name = "band"\nspec = "{spec}"\nepsilon = 0.01\n[grid]\n'
                         f"size = [2, 2]\nstart = [0, 0]\n[regions]\nA = [[1, 1]]\n"
                         f"[distributions]\n{laws}\n")
        mem, size = ["--max-memory", rng.choice(("20M", "200M", "1G"))], None
        size = dict(_MEMORY)[mem[1]]
        return Case(kind, ["solve", str(model), "-q", "--time-limit", "60", *mem],
                    max_memory=size, show=f"{k} events with bands")
    if kind == "sweep results":
        out = rng.choice(("r.csv", "r.parquet", "zero.csv", "full.csv", "fifo.csv",
                          "adir", "/proc/x.csv", "/sys/x.csv", "junk.csv", "nodir/r.csv",
                          "good.csv"))
        argv = ["sweep", str(f / "s.toml"), "-o", out if out.startswith("/") else str(f / out),
                "-q"]
        if out in ("r.csv", "r.parquet"):
            files.fresh(out)
        if rng.random() < 0.2:
            argv += ["--dask", rng.choice(("not an address", "tcp://", "x:99999", ""))]
        return Case(kind, argv, show=f"sweep -o {out}", results=None)
    if kind == "concurrent sweeps":
        out = files.fresh("c.csv")
        argv = ["sweep", str(f / "s.toml"), "-o", str(out), "-q"]
        kill = rng.choice((None, 9, 2, 15))
        return Case(kind, argv, twin=list(argv), twin_delay=rng.uniform(0.0, 2.0), kill=kill,
                    kill_after=rng.uniform(0.5, 4.0), results=out,
                    show=f"two sweeps, the first {'killed by ' + str(kill) if kill else 'kept'}")
    if kind == "controller file":
        good = f / "good.npz"
        name = rng.choice(("good", "truncated", "flipped", "forged", "bomb", "fifo", "zero",
                           "pickle", "adir", "empty"))
        path = _controller(rng, f, name, good)
        code = _LOAD.format(path=str(path))
        if not good.exists():
            code = _SAVE.format(model=str(f / "tiny.toml"), path=str(good)) + code
        return Case(kind, [], python=code, show=f"Controller.load of a {name} file")
    fault = rng.choice(_FAULTS)
    model = f / "world.toml"
    model.write_text(f'name = "w"\nspec = "F[0,5] goal"\n[python]\nworld = "bw:make"\n'
                     f'kwargs = {{ fault = "{fault}", state = {rng.randint(0, 3)}, '
                     f"seed = {rng.randint(0, 99)} }}\n")
    return Case("python world", ["solve", str(model), "-q", "--time-limit", "20", *mem],
                max_memory=size, show=f"a world with the fault {fault}")


def _controller(rng: random.Random, f: Path, name: str, good: Path) -> Path:
    """A controller file of the kind ``name`` (the good one is written by the case)."""
    path = f / f"{name}.npz"
    if name == "good":
        return good
    if name == "fifo":
        if not path.exists():
            os.mkfifo(path)
        return path
    if name == "zero":
        if not os.path.lexists(path):
            os.symlink("/dev/zero", path)
        return path
    if name == "adir":
        return f / "adir"
    if name == "bomb":
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
            with z.open("q.npy", "w", force_zip64=True) as member:
                chunk = bytes(1 << 20)
                for _ in range(rng.choice((64, 600))):  # 64 MB or 600 MB of zeros
                    member.write(chunk)
        return path
    if name == "pickle":
        path.write_bytes(b"\x80\x04\x95" + bytes(rng.randrange(256) for _ in range(64)))
        return path
    if name == "empty":
        path.write_bytes(b"")
        return path
    raw = good.read_bytes() if good.exists() else b"PK\x03\x04"
    if name == "truncated":
        path.write_bytes(raw[: rng.randrange(max(len(raw), 1))])
    elif name == "flipped":
        data = bytearray(raw)
        for _ in range(rng.randint(1, 20)):
            i = rng.randrange(len(data))
            data[i] = rng.randrange(256)
        path.write_bytes(bytes(data))
    else:  # forged: a member's header declares a huge array
        import numpy as np

        header = np.lib.format.header_data_from_array_1_0(np.zeros(4))
        header["shape"] = (rng.choice((10**8, 10**9, 10**12)),)
        buf = io.BytesIO()
        np.lib.format.write_array_header_1_0(buf, header)
        with zipfile.ZipFile(path, "w") as z:
            z.writestr("q.npy", buf.getvalue() + bytes(64))
    return path


def results_damage(path: Path, points: int = SWEEP_POINTS) -> list[str]:
    """What is wrong with a sweep's results file after concurrent writers and kills: a
    point twice, a line that is not whole before the last one, more rows than points."""
    if not path.exists():
        return []
    lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    if not lines:
        return []
    rows = list(csv.reader(lines))
    header, body = rows[0], rows[1:]
    problems = []
    whole = [r for r in body if len(r) == len(header)]
    if len(body) - len(whole) > 1 or (body and len(body[-1]) == len(header)
                                      and len(whole) != len(body)):
        problems.append("a cut line before the last")
    try:
        at = [header.index("constants.T"), header.index("distributions.mu.geometric")]
    except ValueError:
        return [*problems, "no parameter columns"]
    keys = [tuple(r[i] for i in at) for r in whole]
    if len(set(keys)) != len(keys):
        problems.append("a point twice")
    if len(whole) > points:
        problems.append("more rows than points")
    return problems

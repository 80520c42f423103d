"""The fuzz campaign of issue 12: formulas, model files and command lines thrown at the
``mitld-lp`` command, every run in a worker process under a memory and a time limit.

What is run (each input through :func:`mitld_lp.cli.main`, as a user would type it):

* formulas: ``check FORMULA``; when the answer is "supported", every inline law
  ``D[family(args)]`` of the formula is also built (``distributions.from_spec``): a law
  ``check`` accepts but cannot be built is an *accepted invalid law*;
* model files: a bundled ``models/*.toml`` mutated (keys dropped, added, renamed to
  unicode and control characters, values of the wrong type, out of range, huge, nested
  hundreds of levels deep, the text cut or spliced), then ``info FILE --max-states N
  --time-limit T``;
* command lines: random arguments for every verb on tiny models, with output files that
  already exist (they must not change without ``--force``).

Each outcome is classified by the exit code (0 ok, 2 user error, 3 stop, 1 internal
error) or by how the worker ended (killed by a signal or the memory limit: crash; over
the time limit: timeout).  Independently of the code, every run is also checked for the
one-error-path promise: stderr lines are printable, an exit 2 says ``error:`` on exactly
one line, and no existing output file was overwritten without ``--force``.

The workers are started with ``resource.setrlimit(RLIMIT_AS, ...)`` (default 2 GB) in
``preexec_fn``; a worker that dies, times out, or leaves a command thread running (a
``--time-limit`` stop) is replaced before the next run.

Usage: ``python experiments/fuzz.py --quick`` (about 100 of each, into the scratch
folder ``experiments/out``); ``python experiments/fuzz.py`` (10,000 formulas, 2,000
model files, 500 command lines) writes ``experiments/results/fuzz.md``; ``--formulas N
--models N --cli N`` choose the counts.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import platform
import random
import re
import resource
import select
import subprocess
import sys
import threading
import time
import tomllib
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
MODELS = ROOT / "models"
SCRATCH = HERE / "out"
RESULTS = HERE / "results"
GRID_MODELS = ("bus_grid", "bus_grid_case2", "patrol", "red_light")

# --------------------------------------------------------------------------- generators
# Every generator takes a random.Random, so that the hypothesis tests can drive them with
# st.randoms() and a campaign is reproducible from its seed.

FAMILIES = ("geometric", "pmf", "poisson", "uniform", "exponential", "weibull", "gamma",
            "scipy", "nbinom", "zipfian", "")
OPERATORS = ("!", "~", "¬", "&", "&&", "∧", "|", "||", "∨", "->", "→", "X", "F", "G",
             "◇", "□", "U", "𝒰", "R", "D", "true", "false", "⊤", "⊥", "(", ")", "[", "]",
             ",", "<=", "≤", "-")
NUMBERS = ("0", "1", "2", "3", "10", "-1", "0.5", "1.5", "-0.1", ".5", "1e308", "1e999",
           "1e-320", "2.", "99999999999999999999", "1_000", "0x10", "nan", "inf")
STRANGE = ("\x00", "\n", "\r", "\t", "\x1b[31m", "\x7f", "\u200b", "\u202e", "é", "Ω",
           "🙂", "\ufeff", "\\", '"', "'", "#", "{", "}", "=", ";")


def _char(rng: random.Random) -> str:
    """Any Unicode scalar value except surrogates, weighted towards ASCII."""
    if rng.random() < 0.6:
        return chr(rng.randrange(0, 128))
    while True:
        c = rng.randrange(0, 0x110000)
        if not 0xD800 <= c < 0xE000:
            return chr(c)


def random_text(rng: random.Random, max_len: int = 30) -> str:
    """Arbitrary text (control characters, unicode, symbols)."""
    return "".join(_char(rng) for _ in range(rng.randrange(max_len + 1)))


def _name(rng: random.Random) -> str:
    return rng.choice(("p", "q", "A", "b1", "e", "mu", "F1", "Xp", "true_", "_", "a" * 40,
                       "F", "D", "U", "é", "a b"))


def _interval(rng: random.Random) -> str:
    lo, hi = rng.choice(NUMBERS[:6]), rng.choice(NUMBERS)
    return rng.choice((f"[{lo},{hi}]", f"[{hi},{lo}]", f"<={hi}", "", "", f"[{lo}]"))


def _law(rng: random.Random) -> str:
    family = rng.choice(FAMILIES)
    args = [rng.choice(NUMBERS + ("p", "nbinom", "zipfian", "binom")) for _ in
            range(rng.randrange(4))]
    if rng.random() < 0.3:
        return rng.choice(("mu", "mu1", "m2"))
    return f"{family}({', '.join(args)})"


def random_formula(rng: random.Random, depth: int = 4) -> str:
    """A formula shaped by the grammar, with random (often invalid) bounds and laws."""
    if depth <= 0 or rng.random() < 0.25:
        return rng.choice((_name(rng), "true", "false", "⊤", "p", "q"))
    sub = lambda: random_formula(rng, depth - 1)  # noqa: E731
    op = rng.randrange(9)
    if op == 0:
        return f"{rng.choice(('!', '~', '¬', 'X'))}{sub()}"
    if op in (1, 2):
        return f"{rng.choice(('F', 'G', '◇', '□'))}{_interval(rng)} {sub()}"
    if op == 3:
        return f"({sub()} {rng.choice(('U', 'R', '𝒰'))}{_interval(rng)} {sub()})"
    if op == 4:
        return f"D[{_law(rng)}] {rng.choice(('e', 'e1', 'b', 'p'))}"
    if op == 5:
        return f"({sub()} -> {sub()})"
    return f"({sub()} {rng.choice(('&', '|', '&&', '∨'))} {sub()})"


def _mutate_text(rng: random.Random, text: str) -> str:
    """Delete, insert, replace or duplicate a few characters or a slice."""
    for _ in range(rng.randint(1, 3)):
        i = rng.randrange(len(text) + 1)
        j = min(len(text), i + rng.randrange(1, 8))
        match rng.randrange(5):
            case 0:
                text = text[:i] + text[j:]
            case 1:
                text = text[:i] + rng.choice(STRANGE + OPERATORS + NUMBERS) + text[i:]
            case 2:
                text = text[:i] + _char(rng) + text[j:]
            case 3:
                text = text[:i] + text[i:j] * rng.randint(2, 50) + text[j:]
            case _:
                text = text[:i]
    return text


def plausible_law(rng: random.Random) -> str:
    """An inline law with numeric arguments, in or out of its family's range."""
    family = rng.choice(FAMILIES[:8])
    numbers = ("0", "1", "2", "0.5", "0.3", "1.5", "-1", "-0.1", "1e-9", "1e308", "1e6", "1e9",
               "100000000", "99999999999999999999", "3", "7")
    args = [rng.choice(numbers) for _ in range(rng.choice((0, 1, 1, 2, 2, 3)))]
    if family == "scipy":
        args.insert(0, rng.choice(("nbinom", "zipfian", "binom", "norm", "nope", "inf")))
    return f"{family}({', '.join(args)})"


def formula_text(rng: random.Random) -> str:
    """One fuzzed formula: grammar-shaped, an inline law, token soup, mutated, or
    arbitrary text."""
    kind = rng.random()
    if kind < 0.1:
        return f"D[{plausible_law(rng)}] e & F[0,{rng.choice((2, 10, 1000))}] (e & p)"
    if kind < 0.35:
        return random_formula(rng)
    if kind < 0.6:
        tokens = OPERATORS + NUMBERS + ("p", "q", "e1", "geometric", "pmf", "(", ")")
        return rng.choice(("", " ", "\n")).join(
            rng.choice(tokens) for _ in range(rng.randrange(1, 25)))
    if kind < 0.85:
        return _mutate_text(rng, random_formula(rng))
    return random_text(rng)


# --------------------------------------------------------------------------- TOML


def _toml_string(s: str) -> str:
    out = []
    for c in s:
        if c in '"\\':
            out.append("\\" + c)
        elif ord(c) < 0x20 or ord(c) == 0x7F:
            out.append(f"\\u{ord(c):04X}")
        else:
            out.append(c)
    return '"' + "".join(out) + '"'


def _toml_key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else _toml_string(k)


def toml_value(v: Any) -> str:
    """``v`` as a TOML value (tables inline)."""
    if isinstance(v, Raw):
        return v.text
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _toml_string(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"no TOML for {type(v).__name__}")


def to_toml(doc: dict[str, Any]) -> str:
    """A document as TOML: one ``key = value`` line per top-level key."""
    return "".join(f"{_toml_key(k)} = {toml_value(v)}\n" for k, v in doc.items())


def random_value(rng: random.Random, depth: int = 2) -> Any:
    """A TOML value of any type: out-of-range, huge, non-finite, unicode, nested."""
    match rng.randrange(9):
        case 0:
            return rng.random() < 0.5
        case 1:
            return rng.choice((-1, 0, 1, 2, 3, 5, 7, 100, 2**31, 2**63 - 1, -(2**63), 10**30))
        case 2:
            return rng.choice((0.0, -0.0, 0.5, 1.0, 1.5, -0.1, 0.7, 1e-300, 5e-324, 1e300,
                               1.7976931348623157e308, math.nan, math.inf, -math.inf))
        case 3:
            return rng.choice(("", " ", "grid", "F", "a b", "é", "\x1b[2J", "x\ny",
                               "\x00")) if rng.random() < 0.5 else random_text(rng, 12)
        case 4:
            return random_formula(rng, 3)
        case 5 | 6 if depth > 0:
            return [random_value(rng, depth - 1) for _ in range(rng.randrange(5))]
        case 7 if depth > 0:
            return {random_key(rng): random_value(rng, depth - 1) for _ in range(rng.randrange(3))}
    return rng.choice((0, 1, -5, 0.25))


def random_key(rng: random.Random) -> str:
    return rng.choice(("x", "size", "start", "slip", "geometric", "pmf", "A", "F", "true",
                       "", " ", "é", "a.b", "\n", "\x1b[31m", "\x00", "\u202e", "mu1")) \
        if rng.random() < 0.7 else random_text(rng, 8)


@dataclass(frozen=True, slots=True)
class Raw:
    """TOML text put in as it is (a value nested too deeply to build as data)."""

    text: str


def deep(rng: random.Random, levels: int) -> Raw:
    """A value nested ``levels`` deep in arrays and inline tables."""
    text = toml_value(rng.choice((1, "x", 0.5)))
    for _ in range(levels):
        text = f"[{text}]" if rng.random() < 0.5 else f"{{ a = {text} }}"
    return Raw(text)


def _paths(doc: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every key path (dict keys and list indices) below ``doc``."""
    out: list[tuple[Any, ...]] = []
    items = doc.items() if isinstance(doc, dict) else enumerate(doc) if isinstance(
        doc, list) else ()
    for k, v in items:
        out.append(prefix + (k,))
        out.extend(_paths(v, prefix + (k,)))
    return out


def _parent(doc: Any, path: tuple[Any, ...]) -> Any:
    for k in path[:-1]:
        doc = doc[k]
    return doc


def plausible(rng: random.Random, doc: dict[str, Any]) -> None:
    """A change that keeps the file well formed: a grid size, slip, epsilon, law or
    deadline picked from in-range, extreme and huge values (the budgets' territory)."""
    grid = doc.get("grid")
    match rng.randrange(5):
        case 0 if isinstance(grid, dict):
            n = rng.choice((1, 2, 5, 20, 100, 300, 1000, 10**4, 10**6))
            grid["size"] = [n, rng.choice((1, 2, n))]
        case 1 if isinstance(grid, dict):
            grid["slip"] = rng.choice((0.0, 0.5, 0.25, 1e-12, 0.4999999))
        case 2:
            doc["epsilon"] = rng.choice((1e-300, 1e-12, 1e-6, 0.5, 0.999999))
        case 3 if isinstance(doc.get("distributions"), dict) and doc["distributions"]:
            name = rng.choice(sorted(doc["distributions"]))
            law = plausible_law(rng)
            family, _, args = law.partition("(")
            values: list[Any] = [tomllib.loads(f"x = {a}")["x"] if a[0].isdigit() or a[0] == "-"
                                 else a for a in args.rstrip(")").split(", ") if a]
            doc["distributions"][name] = {family: values if len(values) != 1 or family in (
                "pmf", "uniform", "weibull", "gamma", "scipy") else values[0]}
        case _ if isinstance(doc.get("spec"), str):
            bound = rng.choice((0, 30, 1000, 10**6))
            doc["spec"] = re.sub(r"\[0,(\d+)\]", f"[0,{bound}]", doc["spec"])


def mutate_model(rng: random.Random, doc: dict[str, Any]) -> str:
    """A bundled model's document with one to three mutations, as TOML text (sometimes
    cut or spliced at the text level as well); a third of them only plausible changes."""
    doc = json.loads(json.dumps(doc))  # a deep copy of plain data
    if rng.random() < 0.35:
        plausible(rng, doc)
        return to_toml(doc)
    for _ in range(rng.choice((1, 1, 1, 2, 3))):
        paths = _paths(doc)
        path = rng.choice(paths)
        parent, key = _parent(doc, path), path[-1]
        match rng.randrange(9):
            case 0:  # drop
                del parent[key]
            case 1 | 2 | 8:  # wrong type, out of range, huge, non-finite, unicode
                parent[key] = random_value(rng)
            case 3:  # a number nudged, in or out of range, or made huge
                v = parent[key]
                if isinstance(v, int | float) and not isinstance(v, bool):
                    parent[key] = rng.choice((-v, v * 10**rng.randint(1, 30), v + 1, v - 1,
                                              0, float(v), v * 2, v / 2, rng.randint(0, 12),
                                              10**rng.randint(2, 8), rng.random()))
                else:
                    parent[key] = random_value(rng)
            case 4 if isinstance(parent, dict):  # rename (unicode, control characters)
                parent[random_key(rng)] = parent.pop(key)
            case 5 if isinstance(parent, dict):  # an unknown key
                parent[random_key(rng)] = random_value(rng)
            case 6:  # nested deeply
                parent[key] = deep(rng, rng.choice((2, 10, 100, 300, 600, 2000)))
            case _:  # another spec
                doc["spec"] = formula_text(rng)
    text = to_toml(doc)
    if rng.random() < 0.15:
        text = _mutate_text(rng, text)
    return text


def base_documents() -> dict[str, dict[str, Any]]:
    """The bundled grid models, parsed."""
    return {name: tomllib.loads((MODELS / f"{name}.toml").read_text()) for name in GRID_MODELS}


# --------------------------------------------------------------------------- command lines

TINY = """name = "tiny"
spec = "D[mu] e & F(e & F[0,2] A)"
epsilon = 0.05
[grid]
size = [2, 2]
start = [0, 0]
slip = 0.1
[regions]
A = [[1, 1]]
[distributions]
mu = { geometric = 0.5 }
"""
"""A model every verb solves in a fraction of a second (a memoryless event)."""

TINY_TRUNCATED = TINY.replace("geometric = 0.5", "pmf = [0.2, 0.3, 0.5]").replace(
    '"tiny"', '"tiny_pmf"')
"""The same with a law of finite support (a truncation point, two solves)."""

SENTINEL = "do not overwrite\n"


@dataclass(frozen=True, slots=True)
class CliFiles:
    """The files a random command line may name, in a scratch folder."""

    folder: Path

    def prepare(self) -> None:
        """Write the models and reset the existing output files to the sentinel."""
        f = self.folder
        f.mkdir(parents=True, exist_ok=True)
        (f / "tiny.toml").write_text(TINY)
        (f / "tiny_pmf.toml").write_text(TINY_TRUNCATED)
        (f / "empty.toml").write_text("")
        (f / "binary.toml").write_bytes(b"\xff\xfe\x00name = 1")
        (f / "adir.drn").mkdir(exist_ok=True)
        for name in self.existing:
            (f / name).write_text(SENTINEL)
        for name in ("new.drn", "new.mps", "new.lp", "new.dot"):
            (f / name).unlink(missing_ok=True)

    existing = ("old.drn", "old.mps", "old.lp", "old.dot", "old.txt")

    def overwritten(self) -> list[str]:
        return [n for n in self.existing if (self.folder / n).read_text() != SENTINEL]


def _output(rng: random.Random, folder: Path, suffix: str) -> str:
    return rng.choice((
        str(folder / f"old{suffix}"), str(folder / f"new{suffix}"), str(folder / "old.txt"),
        str(folder / "adir.drn"), str(folder / "nodir" / f"x{suffix}"), "/dev/full",
        f"/nonexistent/x{suffix}", "", str(folder / "old.mps"), str(folder / "old.drn"),
    ))


def random_argv(rng: random.Random, folder: Path) -> list[str]:
    """A random command line for a random verb (cheap: tiny models, small budgets)."""
    verb = rng.choice(("check", "dta", "info", "solve", "export", "simulate", "simulate",
                       "solve", "nope", "--version", "--help", ""))
    models = [str(folder / n) for n in ("tiny.toml", "tiny_pmf.toml", "empty.toml",
                                         "binary.toml", "missing.toml", "adir.drn")]
    argv = [verb]
    if verb in ("check", "dta"):
        argv.append(random_formula(rng, 3) if rng.random() < 0.8 else formula_text(rng))
        if verb == "dta" and rng.random() < 0.5:
            argv += ["--dot", _output(rng, folder, ".dot")]
    elif verb in ("info", "solve", "export", "simulate"):
        argv.append(rng.choice(models[:2]) if rng.random() < 0.8 else rng.choice(models))
        argv += ["--max-states", rng.choice(("2000", "2000", "50", "1", "0", "-3", "x",
                                             "1e3", "99999999999999999999"))]
        if rng.random() < 0.3:
            argv += ["--epsilon", rng.choice(("0.01", "0.2", "0", "1", "-1", "nan", "inf",
                                              "1e-300", "x"))]
        if rng.random() < 0.15:
            argv.append("--no-clock-reduction")
    options: list[tuple[str, Callable[[], str] | None]] = [
        ("--json", None), ("-q", None), ("-v", None), ("--force", None), ("--bogus", None),
        ("--time-limit", lambda: rng.choice(("30", "0.01", "0", "-1", "nan", "inf", "x"))),
    ]
    if verb == "solve":
        options += [("--method", lambda: rng.choice(("lp", "vi", "LP", "x"))),
                    ("--solver", lambda: rng.choice(("clarabel", "HIGHS", "NOPE", "", "scs"))),
                    ("--backend", lambda: rng.choice(("cvxpy", "direct", "x")))]
    if verb == "export":
        options += [("--lp", lambda: _output(rng, folder, rng.choice((".mps", ".lp")))),
                    ("--drn", lambda: _output(rng, folder, ".drn")), ("--upper", None)]
    if verb == "simulate":
        options += [("-n", lambda: rng.choice(("1", "50", "0", "-5", "1000000000000", "x"))),
                    ("--seed", lambda: rng.choice(("0", "7", "-1", "2**64", "x"))),
                    ("--max-steps", lambda: rng.choice(("1", "30", "0", "-1", "10**9")))]
    for opt, value in rng.sample(options, rng.randint(0, min(4, len(options)))):
        argv.append(opt)
        if value is not None and rng.random() < 0.95:
            argv.append(value())
    if verb == "simulate" and "-n" not in argv:
        argv += ["-n", "50"]  # keep the default 10,000 rollouts out of a fuzz run
    if rng.random() < 0.1:
        i = rng.randrange(len(argv) + 1)
        argv.insert(i, rng.choice(("--", "-", "extra", "\x1b[31m", "é", "--json=1")))
    return argv


# --------------------------------------------------------------------------- one run


def stderr_problems(code: int, err: str) -> list[str]:
    """Breaks of the one-error-path promise visible on stderr."""
    problems = []
    lines = err.splitlines()
    if any(not line.isprintable() for line in lines):
        problems.append("non-printable stderr")
    if code == 2 and sum("error:" in line for line in lines) != 1:
        problems.append("exit 2 without exactly one error line")
    if code not in (0, 1, 2, 3, 130):
        problems.append(f"exit code {code}")
    return problems


def run_main(argv: list[str]) -> tuple[int, str, str]:
    """``main(argv)`` with its stdout and stderr captured."""
    from mitld_lp.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def law_problem(text: str) -> str | None:
    """For a formula ``check`` accepted: does every inline law build?  ``None`` if so,
    else what the builder said."""
    from mitld_lp.distributions import DistributionError, from_spec
    from mitld_lp.logic.fragment import check
    from mitld_lp.logic.parser import parse
    from mitld_lp.logic.syntax import DistLiteral

    for _, mu in check(parse(text)).events:
        if isinstance(mu, DistLiteral):
            try:
                from_spec(mu)
            except DistributionError as exc:
                return f"accepted invalid law {mu}: {exc}"
            except Exception as exc:  # noqa: BLE001 - exactly what the campaign looks for
                return f"law builder crash {type(exc).__name__} on {mu}"
    return None


def run_one(item: dict[str, Any]) -> dict[str, Any]:
    """One run (in the worker): the exit code, the first error line, the problems."""
    files = CliFiles(Path(item["folder"])) if item["kind"] == "cli" else None
    if files is not None:
        files.prepare()
    code, _out, err = run_main(item["argv"])
    problems = stderr_problems(code, err)
    if item["kind"] == "formula" and code == 0:
        bad = law_problem(item["argv"][-1])
        if bad:
            problems.append(bad)
    if files is not None and "--force" not in item["argv"]:
        problems += [f"overwrote {n} without --force" for n in files.overwritten()]
    said = [line for line in err.splitlines() if "error:" in line or "stopped:" in line]
    return {"code": code, "said": said[-1][:300] if said else "", "problems": problems}


def worker() -> None:
    """Read one JSON item a line from stdin, answer one JSON line each on the original
    stdout (fd 1 itself goes to /dev/null: native solvers print there)."""
    proto = os.fdopen(os.dup(1), "w")
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    for line in sys.stdin:
        item = json.loads(line)
        try:
            answer = run_one(item)
        except BaseException as exc:  # noqa: BLE001 - reported as a crash, then we end
            answer = {"code": -1, "said": f"worker: {type(exc).__name__}: {exc}"[:300],
                      "problems": [], "dead": True}
        answer["dirty"] = threading.active_count() > 1  # a command thread still running
        proto.write(json.dumps(answer) + "\n")
        proto.flush()
        if answer.get("dirty") or answer.get("dead"):
            return


# --------------------------------------------------------------------------- the parent

OUTCOMES = ("ok (0)", "user error (2)", "budget stop (3)", "time limit (3)",
            "out of memory (3)", "internal error (1)", "crash", "timeout")
FINE = ("ok (0)", "user error (2)", "budget stop (3)")


def _outcome(code: int) -> str:
    return {0: "ok (0)", 2: "user error (2)", 3: "stop (3)", 1: "internal error (1)"}.get(
        code, "crash")


@dataclass
class Tally:
    """Counts of one campaign, and an example input for each kind of failure."""

    name: str
    outcomes: Counter[str] = field(default_factory=Counter)
    problems: Counter[str] = field(default_factory=Counter)
    examples: dict[str, str] = field(default_factory=dict)
    broken: int = 0
    seconds: float = 0.0

    def add(self, outcome: str, said: str, problems: Sequence[str], show: str) -> None:
        if outcome == "stop (3)":
            outcome = ("out of memory (3)" if "out of memory" in said else
                       "time limit (3)" if "time limit" in said else "budget stop (3)")
        self.outcomes[outcome] += 1
        self.broken += bool(problems)
        keys = [re.sub(r"(accepted invalid law \w+).*", r"\1(...)", p) for p in problems]
        if outcome not in FINE:
            keys.append(f"{outcome}: {_normalise(said)}")
        for key in keys:
            self.problems[key] += 1
            self.examples.setdefault(key, show)


def _normalise(said: str) -> str:
    """An error line without its numbers and quoted values, to group failures."""
    said = re.sub(r"'[^']*'|\"[^\"]*\"", "'…'", said)
    return re.sub(r"\d+(\.\d+)?(e[+-]?\d+)?", "N", said)[:160]


class Pool:
    """One worker process at a time, under RLIMIT_AS and a per-run time limit."""

    def __init__(self, memory: int, log: Path) -> None:
        self.memory = memory
        self.log = log
        self.proc: subprocess.Popen[str] | None = None

    def _limit(self) -> None:
        resource.setrlimit(resource.RLIMIT_AS, (self.memory, self.memory))

    def _start(self) -> subprocess.Popen[str]:
        env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
                   OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MALLOC_ARENA_MAX="2")
        with self.log.open("a") as log:
            return subprocess.Popen(
                [sys.executable, str(Path(__file__).resolve()), "--worker"],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log, text=True,
                env=env, preexec_fn=self._limit,
            )

    def stop(self) -> None:
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
            self.proc = None

    def run(self, item: dict[str, Any], seconds: float) -> dict[str, Any]:
        if self.proc is None:
            self.proc = self._start()
        proc = self.proc
        assert proc.stdin is not None and proc.stdout is not None
        try:
            proc.stdin.write(json.dumps(item) + "\n")
            proc.stdin.flush()
        except BrokenPipeError:
            pass
        ready, _, _ = select.select([proc.stdout], [], [], seconds)
        line = proc.stdout.readline() if ready else None
        if line is None:
            self.stop()
            return {"code": None, "outcome": "timeout", "said": f"over {seconds:g} s",
                    "problems": []}
        if not line:
            code = proc.wait()
            self.proc = None
            return {"code": None, "outcome": "crash", "said": f"worker ended with {code}",
                    "problems": []}
        answer = json.loads(line)
        answer["outcome"] = "crash" if answer.get("dead") else _outcome(answer["code"])
        if answer.get("dirty") or answer.get("dead"):
            self.stop()
        return answer


def _show(argv: list[str], model_text: str | None) -> str:
    text = " ".join(repr(a) if not re.fullmatch(r"[\w./:=,-]+", a) else a for a in argv)
    if model_text is not None:
        text += f"  with the file {model_text[:400]!r}"
    return text


def campaign(n_formulas: int, n_models: int, n_cli: int, seed: int, folder: Path,
             memory: int, progress: bool = True) -> list[Tally]:
    """Run the three campaigns; return their tallies."""
    rng = random.Random(seed)
    folder.mkdir(parents=True, exist_ok=True)
    pool = Pool(memory, folder / "workers.log")
    docs = base_documents()
    tallies = []
    try:
        for name, n, seconds in (("formulas", n_formulas, 30.0), ("model files", n_models, 30.0),
                                 ("command lines", n_cli, 60.0)):
            tally = Tally(name)
            t0 = time.perf_counter()
            for i in range(n):
                model_text = None
                if name == "formulas":
                    text = formula_text(rng)
                    item = {"kind": "formula", "argv": ["check", "--", text]}
                elif name == "model files":
                    base = rng.choice(sorted(docs))
                    model_text = mutate_model(rng, docs[base])
                    path = folder / "model.toml"
                    path.write_text(model_text, encoding="utf-8")
                    item = {"kind": "model", "argv": ["info", str(path), "--max-states", "20000",
                                                      "--time-limit", "5"]}
                else:
                    cli = folder / "cli"
                    item = {"kind": "cli", "argv": random_argv(rng, cli), "folder": str(cli)}
                answer = pool.run(item, seconds)
                tally.add(answer["outcome"], answer.get("said", ""), answer.get("problems", []),
                          _show(item["argv"], model_text))
                if progress and (i + 1) % max(1, n // 10) == 0:
                    print(f"  {name}: {i + 1}/{n}", file=sys.stderr, flush=True)
            tally.seconds = time.perf_counter() - t0
            tallies.append(tally)
    finally:
        pool.stop()
    return tallies


def report(tallies: list[Tally], args: argparse.Namespace, seconds: float) -> str:
    """The summary table and the failures, as Markdown."""
    lines = [
        "# Fuzz campaign (experiments/fuzz.py)",
        "",
        f"Date: {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}; machine: {platform.node()}"
        f" ({platform.machine()}, {os.cpu_count()} cores, {platform.system()} "
        f"{platform.release()}), Python {platform.python_version()}; seed {args.seed}; "
        f"memory limit {args.memory_gb:g} GB a worker; {seconds:.0f} s in all.",
        "",
        "Command: `python experiments/fuzz.py " + " ".join(sys.argv[1:]) + "`",
        "",
        "| campaign | runs | " + " | ".join(OUTCOMES) + " | promise broken | seconds |",
        "|---|---:|" + "---:|" * len(OUTCOMES) + "---:|---:|",
    ]
    for t in tallies:
        lines.append(f"| {t.name} | {sum(t.outcomes.values())} | "
                     + " | ".join(str(t.outcomes[o]) for o in OUTCOMES)
                     + f" | {t.broken} | {t.seconds:.0f} |")
    lines += ["", "Exit 3 is split by what stopped the run: a budget checked in time "
              "(`--max-states`), the time limit (model files run with `--max-states 20000 "
              "--time-limit 5`), or "
              "a `MemoryError` under the worker's memory limit (a budget that acted too "
              "late). *crash*: the worker died (signal, or memory exhausted outside Python); "
              "*timeout*: no answer within 30 s (60 s for command lines). *promise broken*: runs "
              "whose exit code was fine but that broke the one-error-path promise (a "
              "non-printable or missing error line, an invalid inline law `check` calls "
              "supported, an output file overwritten without `--force`).",
              "", "## Failures, grouped", ""]
    any_failure = False
    for t in tallies:
        for key, count in t.problems.most_common():
            any_failure = True
            lines.append(f"- {t.name}, {count}x: {key}  \n  e.g. `{t.examples[key][:500]}`")
    if not any_failure:
        lines.append("none")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> list[Tally]:
    ap = argparse.ArgumentParser(description="The fuzz campaign of issue 12 (see the module "
                                 "docstring).")
    ap.add_argument("--quick", action="store_true", help="about 100 of each, scratch folder")
    ap.add_argument("--out", type=Path, help="folder for fuzz.md (default: experiments/results,"
                    " or the scratch folder experiments/out with --quick)")
    ap.add_argument("--formulas", type=int)
    ap.add_argument("--models", type=int)
    ap.add_argument("--cli", type=int)
    ap.add_argument("--seed", type=int, default=12)
    ap.add_argument("--memory-gb", type=float, default=2.0)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        worker()
        return []
    full = (10_000, 2_000, 500) if not args.quick else (100, 100, 100)
    counts = [given if given is not None else default for given, default in
              zip((args.formulas, args.models, args.cli), full, strict=True)]
    out = args.out or (SCRATCH if args.quick else RESULTS)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    tallies = campaign(*counts, seed=args.seed, folder=SCRATCH / "fuzz",
                       memory=int(args.memory_gb * 2**30))
    text = report(tallies, args, time.perf_counter() - t0)
    print(text)
    path = out / "fuzz.md"
    path.write_text(text, encoding="utf-8")
    print(f"wrote {path}", file=sys.stderr)
    return tallies


if __name__ == "__main__":
    main()

"""Generators of fuzzed input for the command line, shared by the fuzz campaign
(``experiments/fuzz.py``) and the property tests (``tests/test_fuzz.py``), which may not
import each other: formulas shaped by the grammar or not, mutated model files, random
command lines over a folder of files that must not be overwritten, and the checks of one
run (:func:`stderr_problems`, :func:`law_problem`).

Every generator takes a :class:`random.Random`, so that hypothesis can drive them with
``st.randoms()`` and a campaign is reproducible from its seed.  Not used by the library.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import random
import re
import tomllib
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

# --------------------------------------------------------------------------- formulas

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


def base_documents(paths: Iterable[Path]) -> dict[str, dict[str, Any]]:
    """Model files to mutate, parsed, by the file's stem."""
    return {p.stem: tomllib.loads(p.read_text(encoding="utf-8")) for p in paths}


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

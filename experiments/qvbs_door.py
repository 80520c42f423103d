"""Every QVBS MDP property through the door (``qvbs.py --all``): per class, answered,
refused with the tool's own reason, and inside the reference.

Each parameter instance QVBS lists for an MDP family, and each property it gives a result
for (an instance with no result: every property of the family, with no reference), is a
row.  A family is read from its PRISM program and properties file where the folder holds
them, else from its JANI file; a family with neither (Modest or PPDDL originals whose JANI
file is not kept) is a row per result with the reason.  An instance whose QVBS state
count passes ``--max-states`` is a row ``over budget: N states`` and is not run; the
others are posed as a user poses them, one property per run::

    mitld-lp solve FILE.prism --prop FILE.props NAME --const K=2 --json -q \\
        --max-world-states LIMIT --max-memory 4G

(``FILE.jani --prop NAME`` for JANI), in a child process killed after ``--timeout``
seconds.  The row keeps what the tool said: the bracket and its status, the verdict of a
``P>=p`` property, or the refusal (``error`` of the JSON object, exit 2), the budget stop
(exit 3), the timeout, a crash (no JSON).  The constants given are the instance's values
of the constants the files leave open (``const int N;``).

Classes come from the property's text (the PRISM properties file's, or the JANI
expression written as PCTL): unbounded ``P``, step-bounded ``P`` (``F<=k``, ``U<=k``),
time-bounded ``P``, reward-bounded ``P`` (``F^{rew{...}<=b}``, ``U{"r"}<=b``),
qualitative ``P`` (``P>=1``, ``P<=0``, ``P>0``, ``P<1``), ``P`` against another
threshold, expected reward until a target (``R[...]=? [F ...]``, ``T=? [F ...]``),
one against a bound (``R{"r"}<=b [F ...]``, ``T>=b [F ...]``), cumulative ``C<=k``,
instantaneous ``I=k``, long-run average / steady state, other.

Inside the reference: QVBS's exact references (``num/den``, or an integer) are compared
as ``Fraction``\\ s with the bracket's two floats read as the rationals they are, no
tolerance; a float reference (no fraction given) and an interval reference are compared
as given and counted apart ("float ref", "interval ref"); a qualitative reference
(``true``/``false``) against the verdict the bracket decided.  Only a certified answer
can be inside.
"""

from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from collections import Counter, defaultdict
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

from _common import ROOT, markdown_table, write_csv, write_text

CLASSES = (
    "P unbounded", "P step-bounded", "P time-bounded", "P reward-bounded",
    "P qualitative", "P threshold", "R reach (F)", "R threshold (R~b)", "R cumulative (C<=k)",
    "R instantaneous (I=k)", "LRA / steady-state", "other",
)
#: A property's class from QVBS's type of it, for the rows with no text to read.
BY_TYPE = {"prob-reach": "P unbounded", "prob-reach-step-bounded": "P step-bounded",
           "prob-reach-time-bounded": "P time-bounded",
           "prob-reach-reward-bounded": "P reward-bounded", "exp-reward": "R reach (F)",
           "exp-steps": "R reach (F)", "exp-time": "R reach (F)",
           "exp-reward-step-bounded": "R cumulative (C<=k)",
           "steady-state-prob": "LRA / steady-state", "steady-state-reward": "LRA / steady-state"}
PRISM_SUFFIXES = (".prism", ".nm", ".pm")
PROPS_SUFFIXES = (".props", ".pctl", ".prctl")


@dataclass(frozen=True)
class Case:
    """One property of one parameter instance of a QVBS family (one table row)."""

    family: str
    instance: str
    prop: str
    kind: str  # QVBS's type of the property ("prob-reach", "exp-reward", ...)
    reference: Any  # the index's value as given (None: no result)
    states: int | None  # QVBS's state count
    constants: Mapping[str, Any] = field(default_factory=dict)
    model: Path | None = None
    props: Path | None = None  # the PRISM properties file (None for JANI)
    text: str = ""  # the property as PCTL
    why: str = ""  # why it is not run ("" when it is)

    @property
    def name(self) -> str:
        return f"{self.instance}.{self.prop}"

    @property
    def cls(self) -> str:
        """The class of the property's text; without one (no model file), of QVBS's
        type of it."""
        if self.text:
            return classify(self.text)
        if isinstance(self.reference, bool):
            return "P qualitative"
        return BY_TYPE.get(self.kind, "other")


# --------------------------------------------------------------------------- classes


def classify(text: str) -> str:
    """The class of a PCTL property as PRISM or Storm write it."""
    t = " ".join(text.split())
    head = re.match(r"^(P|R|T|S|LRA)\s*(?:\[[^\]]*\]\s*)?(?:\{[^}]*\})?\s*(?:\[[^\]]*\]\s*)?"
                    r"(min|max)?\s*"
                    r"(=\s*\?|>=|<=|>|<)\s*([0-9.eE+-]*)\s*\[(.*)\]\s*$", t)
    if not head:
        return "other"
    op, _, how, threshold, body = head.groups()
    if op in ("S", "LRA") or re.match(r"^\s*(S|LRA)\s*$", body):
        return "LRA / steady-state"
    if op in ("R", "T"):
        if re.match(r"^\s*C\s*<=", body):
            return "R cumulative (C<=k)"
        if re.match(r"^\s*I\s*=", body):
            return "R instantaneous (I=k)"
        if re.match(r"^\s*F\b", body):  # R=? (min, max) or a bound R<=b, T>=b
            return "R reach (F)" if how.startswith("=") else "R threshold (R~b)"
        return "other"
    if re.search(r"\^\{|rew\{|(?:F|U)\s*\{\s*\"", body):
        return "P reward-bounded"
    if re.search(r"(?:F|U)\s*\[?\s*time\s*<=|(?:F|U)\s*\[\s*[0-9.]+\s*,", body):
        return "P time-bounded"
    if re.search(r"(?:^|[\s)\"])(?:F|U)\s*(?:<=|<|\[)", body):
        return "P step-bounded"
    if not how.startswith("="):
        value = float(threshold) if threshold else math.nan
        qualitative = (how in (">=", "<") and value == 1) or (how in ("<=", ">") and value == 0)
        return "P qualitative" if qualitative else "P threshold"
    if re.match(r"^\s*X\b", body):
        return "other"
    return "P unbounded"


_JANI_OPS = {"∧": "&", "∨": "|", "=": "=", "≠": "!=", "<": "<", "≤": "<=", ">": ">",
             "≥": ">=", "+": "+", "-": "-", "*": "*", "/": "/", "⇒": "=>"}


def jani_text(expr: Any) -> str:
    """A JANI property expression written as PCTL (enough to classify and to read)."""
    if isinstance(expr, bool):
        return "true" if expr else "false"
    if isinstance(expr, int | float | str):
        return str(expr)
    if not isinstance(expr, dict):
        return "?"
    op = expr.get("op")
    if op == "filter":
        return jani_text(expr.get("values"))
    if op in ("Pmin", "Pmax"):
        return f"{op}=? [{jani_text(expr.get('exp'))}]"
    if op in ("Emin", "Emax"):
        reward = f'R{{"{jani_text(expr.get("exp"))}"}}{op[1:]}=? '
        if "reach" in expr:
            return reward + f"[F {jani_text(expr['reach'])}]"
        instant = expr.get("step-instant", expr.get("time-instant"))
        if instant is not None:
            kind = "C<=" if expr.get("accumulate") else "I="
            return reward + f"[{kind}{jani_text(instant)}]"
        return reward + "[?]"
    if op in ("Smin", "Smax"):
        return f"LRA{op[1:]}=? [{jani_text(expr.get('exp'))}]"
    if op in ("U", "F", "G", "X"):
        bound = ""
        for key, shown in (("step-bounds", ""), ("time-bounds", "time"),
                           ("reward-bounds", "rew")):
            b = expr.get(key)
            if b:
                b = b[0] if isinstance(b, list) else b
                limit = jani_text(b.get("bounds", b).get("upper", "?"))
                bound = (f"^{{rew{{\"{jani_text(b.get('exp'))}\"}}<={limit}}}"
                         if shown == "rew" else f"[{shown}<={limit}]" if shown
                         else f"<={limit}")
        if op == "U":
            return f"{jani_text(expr.get('left'))} U{bound} {jani_text(expr.get('right'))}"
        return f"{op}{bound} {jani_text(expr.get('exp'))}"
    if op in ("¬", "!"):
        return f"!{jani_text(expr.get('exp'))}"
    if op in ("≥", ">", "≤", "<") and isinstance(expr.get("left"), dict) and \
            expr["left"].get("op") in ("Pmin", "Pmax"):
        inner = jani_text(expr["left"])
        return inner.replace("=?", _JANI_OPS[op] + jani_text(expr.get("right")), 1)
    if "left" in expr and "right" in expr:
        return f"({jani_text(expr['left'])} {_JANI_OPS.get(op, op)} {jani_text(expr['right'])})"
    return str(op)


# --------------------------------------------------------------------------- the index


def read_properties(path: Path) -> dict[str, str]:
    """``name -> text`` of a PRISM properties file's named properties."""
    text = "\n".join(line.split("//", 1)[0] for line in path.read_text().splitlines())
    out: dict[str, str] = {}
    for piece in text.split(";"):
        m = re.match(r'^\s*"([^"]+)"\s*:\s*(.+?)\s*$', piece, re.DOTALL)
        if m:
            out[m[1]] = " ".join(m[2].split())
    return out


def open_constants(texts: Iterable[str]) -> set[str]:
    """The constants PRISM texts declare without a value (``const int N;``)."""
    names: set[str] = set()
    for text in texts:
        names |= set(re.findall(r"\bconst\s+(?:int\s+|double\s+|bool\s+)?(\w+)\s*;", text))
    return names


def _jani(path: Path) -> tuple[dict[str, str], set[str]]:
    """``name -> PCTL text`` of a JANI file's properties, and its open constants."""
    model = json.loads(path.read_text(encoding="utf-8-sig"))
    texts = {p["name"]: jani_text(p.get("expression")) for p in model.get("properties", [])}
    return texts, {c["name"] for c in model.get("constants", []) if "value" not in c}


@dataclass(frozen=True)
class Entry:
    """One file entry of a family's ``index.json``."""

    folder: Path
    meta: Mapping[str, Any]
    kinds: Mapping[str, str]  # property name -> QVBS's type
    entry: Mapping[str, Any]
    originals: list[str]
    prism: list[str]  # the original PRISM program(s)
    props: list[str]  # the original properties file(s)


def entries(benchmarks: Path) -> Iterator[Entry]:
    """Every file entry of every MDP family's ``index.json``, in order."""
    for index in sorted((benchmarks / "mdp").glob("*/index.json")):
        meta = json.loads(index.read_text(encoding="utf-8"))
        kinds = {p["name"]: p.get("type", "") for p in meta.get("properties", [])}
        for entry in meta.get("files", []):
            originals = entry.get("original-file", [])
            originals = [originals] if isinstance(originals, str) else originals
            yield Entry(index.parent, meta, kinds, entry, originals,
                        [f for f in originals if f.endswith(PRISM_SUFFIXES)],
                        [f for f in originals if f.endswith(PROPS_SUFFIXES)])


def _read(e: Entry) -> tuple[Path | None, Path | None, dict[str, str], set[str], str]:
    """``(model, properties file, name -> text, open constants, why not)`` of an entry:
    its PRISM program and properties file where the folder holds them, else its JANI
    file, else why it cannot be read."""
    jani = e.folder / e.entry.get("file", "")
    if e.prism and (e.folder / e.prism[0]).is_file():
        model = e.folder / e.prism[0]
        sources = [model.read_text()]
        if not (e.props and (e.folder / e.props[0]).is_file()):
            return model, None, {}, set(), "no PRISM properties file in the folder"
        props = e.folder / e.props[0]
        sources.append(props.read_text())
        return model, props, read_properties(props), open_constants(sources), ""
    if jani.suffix == ".jani" and jani.is_file():
        texts, undefined = _jani(jani)
        return jani, None, texts, undefined, ""
    return None, None, {}, set(), (
        f"not readable: no model file in the folder (original {e.meta.get('original')}: "
        f"{', '.join(e.originals) or '?'}; {e.entry.get('file')} not kept)")


def cases(benchmarks: Path, max_states: int) -> list[Case]:
    """Every row: each result (or, without results, each property) of each instance."""
    rows: list[Case] = []
    for e in entries(benchmarks):
        folder, kinds, entry = e.folder, e.kinds, e.entry
        model, props_path, texts, undefined, why = _read(e)
        fixed = {v["name"]: v["value"] for v in entry.get("file-parameter-values", [])}
        for setting in entry.get("open-parameter-values", []):
            values = {v["name"]: v["value"] for v in setting.get("values", [])}
            constants = {k: v for k, v in {**fixed, **values}.items() if k in undefined}
            counts = [s["number"] for s in setting.get("states", []) if "number" in s]
            states = int(counts[0]) if counts else None
            instance = ".".join([folder.name] + [str(v).lower() for v in
                                                  {**fixed, **values}.values()])
            results = setting.get("results", [])
            wanted = [(r.get("property", "?"), r.get("value")) for r in results] or [
                (p, None) for p in kinds]
            for prop, reference in wanted:
                reason = why
                if not reason and prop not in texts:
                    reason = f"property {prop!r} not in {model.name if model else '?'}"
                if not reason and states is not None and states > max_states:
                    reason = f"over budget: {states:,} states"
                rows.append(Case(folder.name, instance, prop, kinds.get(prop, ""),
                                 reference, states, constants, model, props_path,
                                 texts.get(prop, ""), reason))
    return rows


# --------------------------------------------------------------------------- running


def command(case: Case, max_states: int, max_memory: str) -> list[str]:
    """The door's command line for one row (``python -m mitld_lp`` is ``mitld-lp``)."""
    assert case.model is not None
    prop = [str(case.props), case.prop] if case.props is not None else [case.prop]
    cmd = [sys.executable, "-m", "mitld_lp", "solve", str(case.model), "--prop", *prop,
           "--json", "-q", "--max-world-states", str(max_states), "--max-memory", max_memory]
    if case.constants:
        cmd += ["--const", ",".join(f"{k}={str(v).lower() if isinstance(v, bool) else v}"
                                    for k, v in case.constants.items())]
    return cmd


def run(cmd: Sequence[str], timeout: float) -> dict[str, Any]:
    """The door's JSON object for one property, or ``{"status": "timeout" | "crash"}``
    with the reason; ``seconds`` added.  The child runs in its own session and its
    process group is killed at the timeout."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    started = time.perf_counter()
    child = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env=env, start_new_session=True)
    try:
        out, err = child.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(child.pid, signal.SIGKILL)
        child.communicate()
        return {"status": "timeout", "error": f"over {timeout:g} s",
                "seconds": time.perf_counter() - started}
    except BaseException:  # Ctrl-C: the child's session goes with the harness
        os.killpg(child.pid, signal.SIGKILL)
        raise
    seconds = time.perf_counter() - started
    lines = [line for line in out.splitlines() if line.startswith("{")]
    if not lines:
        tail = (err.strip().splitlines() or ["no output"])[-1]
        return {"status": "crash", "error": f"exit {child.returncode}: {tail[:300]}",
                "seconds": seconds}
    record = json.loads(lines[-1])
    record["seconds"] = seconds
    record["exit"] = child.returncode
    return record


# --------------------------------------------------------------------------- judging


def reference_of(value: Any) -> tuple[str, Any]:
    """``(kind, value)``: "exact" (a Fraction), "float" (a Fraction of the float),
    "interval" (two Fractions), "bool", or "none"."""
    if isinstance(value, bool):
        return "bool", value
    if isinstance(value, int):
        return "exact", Fraction(value)
    if isinstance(value, float):
        return "float", Fraction(value)
    if isinstance(value, dict):
        if "num" in value and "den" in value:
            return "exact", Fraction(int(value["num"]), int(value["den"]))
        if "lower" in value and "upper" in value:
            return "interval", (Fraction(value["lower"]), Fraction(value["upper"]))
        if isinstance(value.get("approx"), int | float):
            return "float", Fraction(value["approx"])
    return "none", None


def outcome(record: Mapping[str, Any]) -> str:
    """answered, refused, budget, timeout or crash."""
    if "lower" in record and "upper" in record and "error" not in record:
        return "answered"
    status = record.get("status")
    if status in ("timeout", "crash", "budget"):
        return str(status)
    return "refused"


def _rational(x: Any) -> Fraction | None:
    x = float(x)
    return Fraction(x) if math.isfinite(x) else None


def judge(reference: Any, record: Mapping[str, Any]) -> str:
    """Whether an answer holds QVBS's reference: yes / NO (exact or qualitative), float
    ref yes/no, interval ref overlaps/apart, undecided, uncertified, '-' (no
    reference or no answer)."""
    kind, ref = reference_of(reference)
    if kind == "none" or outcome(record) != "answered":
        return "-"
    if not record.get("certified"):
        return "uncertified"
    if kind == "bool":
        verdict = record.get("verdict")
        if verdict is None:
            return "undecided" if "comparison" in record else "-"
        return "yes" if verdict == ref else "NO"
    low, high = _rational(record["lower"]), _rational(record["upper"])
    if kind == "interval":
        lo, hi = ref
        apart = (high is not None and high < lo) or (low is None or low > hi)
        return "interval ref apart" if apart else "interval ref overlaps"
    inside = low is not None and high is not None and low <= ref <= high
    if kind == "float":
        return "float ref yes" if inside else "float ref no"
    return "yes" if inside else "NO"


def reason_key(text: str) -> str:
    """A refusal's text with what names the instance taken out (its property and
    formula, the details in parentheses, file paths, quoted names, numbers), so that
    refusals of one kind group together."""
    t = text
    while re.search(r"\([^()]*\)", t):  # the details in parentheses (innermost first)
        t = re.sub(r"\([^()]*\)", "", t)
    t = re.sub(r"^property \S+\s*:\s*", "", t)
    t = re.sub(r"(?:/[^\s:'\"]+)+", "FILE", t)
    t = re.sub(r"'[^']*'", "'…'", t)
    return re.sub(r"\d[\d,.]*(?:e[+-]?\d+)?", "N", t)


# --------------------------------------------------------------------------- the report


COLUMNS = ["instance", "class", "qvbs type", "property", "states", "outcome", "lower",
           "upper", "value", "reference", "inside", "status", "seconds", "reason"]


def row_of(case: Case, record: Mapping[str, Any]) -> list[Any]:
    """One CSV / table row."""
    kind, ref = reference_of(case.reference)
    shown = ("-" if kind == "none" else str(ref).lower() if kind == "bool" else
             f"[{ref[0]}, {ref[1]}]" if kind == "interval" else
             f"{ref} (float)" if kind == "float" else str(ref))
    said = "not run" if case.why else outcome(record)
    answered = said == "answered"
    return [case.instance, case.cls, case.kind, case.text or case.prop,
            "-" if case.states is None else f"{case.states:,}", said,
            repr(record["lower"]) if answered else "",
            repr(record["upper"]) if answered else "",
            str(record.get("verdict", record.get("value", ""))) if answered else "", shown,
            "-" if case.why else judge(case.reference, record),
            str(record.get("status", "")) if answered else "",
            f"{record['seconds']:.2f}" if "seconds" in record else "",
            case.why or ("" if answered else str(record.get("error", "")))]


def summary(rows: Sequence[Sequence[Any]]) -> tuple[list[str], list[list[Any]]]:
    """Per class: rows, answered, inside (exact / qualitative), outside, float or interval
    reference (held / not), not certified, refused, budget stop, timeout, crash, over
    budget, not readable, no reference."""
    header = ["class", "rows", "answered", "inside", "outside", "approx ref held",
              "approx ref not held", "uncertified/undecided", "refused", "budget stop",
              "timeout", "crash", "over budget", "not readable", "no reference"]
    counts: dict[str, Counter[str]] = defaultdict(Counter)
    for r in rows:
        c = counts[r[1]]
        c["rows"] += 1
        said, inside, why = r[5], r[10], r[13]
        if said == "not run":
            c["over budget" if why.startswith("over budget") else "not readable"] += 1
        elif said == "budget":
            c["budget stop"] += 1
        else:
            c[said] += 1
        if said == "answered":
            key = {"yes": "inside", "NO": "outside", "float ref yes": "approx ref held",
                   "interval ref overlaps": "approx ref held",
                   "float ref no": "approx ref not held",
                   "interval ref apart": "approx ref not held",
                   "uncertified": "uncertified/undecided",
                   "undecided": "uncertified/undecided"}.get(inside)
            if key:
                c[key] += 1
        if r[9] == "-":
            c["no reference"] += 1
    table = [[cls] + [counts[cls][h] for h in header[1:]]
             for cls in CLASSES if cls in counts]
    table.append(["all"] + [sum(counts[c][h] for c in counts) for h in header[1:]])
    return header, table


def reasons(rows: Sequence[Sequence[Any]]) -> list[list[Any]]:
    """The refusals grouped: ``[count, outcome, classes, an exact text]``, most first."""
    groups: dict[tuple[str, str], list[Sequence[Any]]] = defaultdict(list)
    for r in rows:
        if r[5] not in ("answered",) and r[13]:
            groups[(r[5], reason_key(r[13]))].append(r)
    out = [[len(members), said, ", ".join(sorted({m[1] for m in members})), members[0][13]]
           for (said, _), members in groups.items()]
    return sorted(out, key=lambda g: (-g[0], g[1], g[3]))


def report(rows: Sequence[Sequence[Any]], head: str) -> str:
    """The markdown report: the command, the per-class counts, the reasons, the rows."""
    header, table = summary(rows)
    grouped = reasons(rows)
    return "\n".join([
        head, "", "### Per class", "", markdown_table(header, table),
        "Answered: the tool gave a bracket (and, for `P~p`, its verdict); inside: "
        "certified and holding QVBS's exact reference (a fraction or an integer, compared "
        "as `Fraction`s with the bracket's floats read exactly; a `P>=1` by its verdict); "
        "approx ref: QVBS gives only a float or an interval, compared as given; budget "
        "stop: the tool stopped at `--max-world-states`/`--max-memory` (exit 3); over "
        "budget: QVBS's state count passes `--max-states`, not run; not readable: the "
        "folder holds no PRISM or JANI file of the family; no reference: QVBS gives no "
        "result for the instance (every property of the family is posed).", "",
        "### Reasons (grouped; the text is the tool's own, of the first row of the group)",
        "", markdown_table(["rows", "outcome", "classes", "reason"],
                           [[g[0], g[1], g[2], g[3].replace("|", "\\|")] for g in grouped]),
        "### Every row", "",
        markdown_table(COLUMNS, [[str(c).replace("|", "\\|") for c in r] for r in rows])])


def main_all(benchmarks: Path, out: Path, max_states: int, timeout: float,
             max_memory: str, families: Sequence[str] | None, head: str,
             say: Callable[[str], None] = print) -> int:
    """Pose every row, write ``qvbs_all.csv`` and ``qvbs_all.md`` into ``out``; exit
    status 1 when an exact or qualitative reference is outside a certified answer."""
    todo = [c for c in cases(benchmarks, max_states) if not families or c.family in families]
    rows: list[list[Any]] = []
    for i, case in enumerate(todo, 1):
        record: dict[str, Any] = {}
        if not case.why:
            record = run(command(case, max_states, max_memory), timeout)
        if "error" in record:  # no path of this machine in the table
            record["error"] = str(record["error"]).replace(str(benchmarks.resolve()), "QVBS")
        row = row_of(case, record)
        rows.append(row)
        say(f"[{i}/{len(todo)}] {case.name} ({row[1]}): {row[5]}"
            + (f" [{row[6]}, {row[7]}] ref {row[9]} inside {row[10]}" if row[5] == "answered"
               else f": {row[13][:160]}") + (f" ({row[12]} s)" if row[12] else ""))
    write_csv(out / "qvbs_all.csv", COLUMNS, rows)
    text = report(rows, head)
    write_text(out / "qvbs_all.md", text + "\n")
    header, table = summary(rows)
    say(markdown_table(header, table))
    return 1 if any(r[10] == "NO" for r in rows) else 0

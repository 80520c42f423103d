"""The Quantitative Verification Benchmark Set's PRISM MDPs, solved through the front door.

Every PRISM-language MDP instance of QVBS (the QComp set, ``ahartmanns/qcomp``,
``benchmarks/mdp/*/index.json``; data CC-BY 4.0) with at most ``--max-states`` reachable
states (2,000,000) and a probability as its reference value is posed as a model file
(``[prism] file``, the instance's constants, ``[labels]`` for the property's state
formulas, the property as an MITLD spec; ``objective = "min"`` for ``Pmin``) and solved
with :func:`mitld_lp.load_model` and :func:`mitld_lp.synthesize` in a child process; the
PRISM text is never edited.  Storm solves the same file and property in this process,
for its time and value.  The table lists per instance: QVBS's state count, the world
states we explored, our certified bracket, QVBS's reference (exact where it gives one),
whether the reference lies inside the bracket, our time (load + solve) and Storm's
(parse + build + check), and their ratio.  Trivial references (0, 1, below 1e-3 or
above 1 - 1e-3) are listed apart and never enter a ratio.  Every instance that is not run
is listed with the reason.

Inside means inside exactly: the bracket's two floats as the solver printed them, read as
the rationals they are (``Fraction(lower)``), against QVBS's exact reference ``num/den``,
with no tolerance (a bracket that misses by one rounding misses); the table prints the
floats in full and, for a miss, how far it is relative to the reference.  A reference
QVBS gives only approximately is compared as given and counted apart (``approx``), never
in the exact tally or the exit status.  ``--exact`` also asks each instance for its exact
optimum (``solve --exact``, within its budget) and says whether that fraction is QVBS's.

Properties are translated as written: ``P(min|max)=? [F phi]`` is ``F t``, ``[F<=k phi]``
is ``F[0,k] t``, ``[psi U phi]`` is ``l U t`` (MITLD's until is PCTL's: ``psi`` at every
step before the first ``phi``), with ``t``, ``l`` the file's label when the state formula
is one label (or ``!`` one label), else a ``[labels]`` entry holding the state formula as
a PRISM expression (labels inlined).  Reward-bounded (``F^{rew...}``), reward and
steady-state properties are not probabilities of the kind a task expresses: listed as not
run.  The deadline families (firewire_dl, zeroconf_dl, wlan_dl) keep their PRISM clock:
their deadline is a state formula of the file (``t>=deadline``), posed as written.

The QVBS files are not part of this repository: give a checkout's ``benchmarks/``
folder::

    git clone https://github.com/ahartmanns/qcomp && \\
        python experiments/qvbs.py --qvbs qcomp/benchmarks
    python experiments/qvbs.py --qvbs qcomp/benchmarks --quick   # up to 20,000 states

The exactness check of issue 40 runs every instance of at most 200,000 states::

    python experiments/qvbs.py --qvbs qcomp/benchmarks --max-states 200000 --exact

``--all`` poses every property of every family instead, PRISM and JANI, probabilities,
rewards and qualitative, through the door (``mitld-lp solve FILE --prop ... --json``) and
reports per class how many are answered, refused (the tool's reason, grouped) and inside
the reference: ``qvbs_all.md`` and ``qvbs_all.csv`` (see :mod:`qvbs_door`)::

    python experiments/qvbs.py --qvbs qcomp/benchmarks --all --max-states 100000 --timeout 120

A full run writes ``qvbs.csv`` and ``qvbs.md`` to ``experiments/out``; ``--quick`` to the
scratch folder.  Exit status 1 when an exact reference lies outside a certified bracket,
or an exact answer is not QVBS's fraction.
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

from _common import ROOT, markdown_table, out_dir, parser, text_table, write_csv, write_text
from qvbs_door import entries, main_all, read_properties

from mitld_lp.logic.syntax import is_proposition_name

QUICK_STATES = 20_000
ALL_QUICK_STATES = 1_000  # --all --quick: the instances of at most 1,000 states
TRIVIAL = 1e-3


@dataclass(frozen=True)
class Instance:
    """One property of one parameter setting of one QVBS family."""

    family: str
    prism: Path
    props: Path
    constants: Mapping[str, bool | int | float]
    prop: str
    reference: Fraction | float
    qvbs_states: int

    @property
    def name(self) -> str:
        values = "-".join(str(v).lower() for v in self.constants.values())
        return f"{self.family}.{values}.{self.prop}" if values else f"{self.family}.{self.prop}"


@dataclass(frozen=True)
class Posed:
    """A property as a model file's spec, labels and objective."""

    spec: str
    labels: dict[str, str] = field(default_factory=dict)
    objective: str = "max"


class NotPosed(Exception):
    """The property is not one a task expresses (the reason is the message)."""


# --------------------------------------------------------------------------- QVBS index


def _reference(value: Any) -> Fraction | float | None:
    if isinstance(value, bool):
        return None
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, dict):
        if "num" in value and "den" in value:
            return Fraction(int(value["num"]), int(value["den"]))
        if isinstance(value.get("approx"), int | float):
            return float(value["approx"])
    return None


def find_instances(
    benchmarks: Path, max_states: int
) -> tuple[list[Instance], list[tuple[str, str]]]:
    """Every instance to run, and ``(what, why not)`` for every one left out."""
    runs: list[Instance] = []
    skipped: list[tuple[str, str]] = []
    for e in entries(benchmarks):
        family, meta, kinds, entry = e.folder, e.meta, e.kinds, e.entry
        prism, props = e.prism, e.props
        if meta.get("original") != "PRISM" or not prism:
            skipped.append((f"{family.name}/{entry.get('file')}",
                            f"not PRISM ({meta.get('original')})"))
            continue
        fixed = {v["name"]: v["value"] for v in entry.get("file-parameter-values", [])}
        for setting in entry.get("open-parameter-values", []):
            constants = {**fixed, **{v["name"]: v["value"] for v in setting.get("values", [])}}
            states = [s["number"] for s in setting.get("states", []) if "number" in s]
            label = f"{family.name} {constants}"
            if not states:
                skipped.append((label, "QVBS gives no state count"))
                continue
            if states[0] > max_states:
                skipped.append((label, f"{states[0]:,} states > {max_states:,}"))
                continue
            for result in setting.get("results", []):
                name = result.get("property", "?")
                kind = kinds.get(name, "")
                reference = _reference(result.get("value"))
                if not kind.startswith("prob"):
                    skipped.append((f"{label} {name}", f"not a probability ({kind})"))
                    continue
                if reference is None:
                    skipped.append((f"{label} {name}", f"qualitative ({kind}, reference "
                                    f"{result.get('value')!r}), not a probability"))
                    continue
                if not props:
                    skipped.append((f"{label} {name}", "no PRISM properties file"))
                    continue
                runs.append(Instance(family.name, family / prism[0], family / props[0],
                                     constants, name, reference, int(states[0])))
    return runs, skipped


# --------------------------------------------------------------------------- posing


def _top_level_until(body: str) -> int | None:
    """The index of the ``U`` of ``body`` outside parentheses and quotes, or None."""
    depth, quoted = 0, False
    for i, c in enumerate(body):
        if c == '"':
            quoted = not quoted
        elif quoted:
            continue
        elif c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif (c == "U" and depth == 0 and (i == 0 or not body[i - 1].isalnum() and
              body[i - 1] != "_") and (i + 1 == len(body) or body[i + 1] in " (<\"!")):
            return i
    return None


def pose(text: str, labels: Mapping[str, str], constants: Mapping[str, Any]) -> Posed:
    """The property ``text`` (``Pmax=? [F "goal"]``) as a spec over ``labels`` (the
    file's ``name -> expression``); ``constants`` are substituted where the property
    uses them: the properties file's own, and the program's open ones (a step bound
    ``F<=B`` with ``B`` left open in the program).  Raises :class:`NotPosed`."""
    m = re.fullmatch(r"\s*P\s*(min|max)\s*=\s*\?\s*\[(.*)\]\s*", text, re.DOTALL)
    if not m:
        raise NotPosed("not a Pmin=?/Pmax=? query")
    body = m[2].strip()
    for name, value in constants.items():
        shown = str(value).lower() if isinstance(value, bool) else str(value)
        body = re.sub(rf"(?<![\w\"]){re.escape(name)}(?![\w\"])", shown, body)
    if "^{" in body or "rew" in body:
        raise NotPosed("reward-bounded path formula")
    extra: dict[str, str] = {}

    def prop(formula: str, role: str) -> str:
        f = formula.strip()
        while f.startswith("(") and f.endswith(")") and _balanced(f[1:-1]):
            f = f[1:-1].strip()
        one = re.fullmatch(r'(!?)\s*"(\w+)"', f)  # a label of the file, or its negation
        if one and one[2] in labels and is_proposition_name(one[2]):
            return one[1] + one[2]

        def inline(match: re.Match[str]) -> str:
            if match[1] not in labels:
                raise NotPosed(f"label {match[1]!r} is not defined by the file")
            return f"({labels[match[1]]})"

        name = f"qvbs_{role}"
        extra[name] = re.sub(r'"(\w+)"', inline, f)
        return name

    at = _top_level_until(body)
    if at is not None:
        right = body[at + 1 :].lstrip()
        bound = re.match(r"<=\s*(\d+)\s*", right)
        window = f"[0,{bound[1]}]" if bound else ""
        right = right[bound.end():] if bound else right
        spec = f"{prop(body[:at], 'left')} U{window} {prop(right, 'target')}"
    else:
        f = re.fullmatch(r"F\s*(?:<=\s*(\d+))?\s*(?=[\s(\"!A-Za-z])(.*)", body, re.DOTALL)
        if not f:
            raise NotPosed(f"path formula {body[:30]!r} is not F or U")
        window = f"[0,{f[1]}]" if f[1] else ""
        spec = f"F{window} {prop(f[2], 'target')}"
    return Posed(spec=spec, labels=extra, objective=m[1])


def _balanced(text: str) -> bool:
    depth = 0
    for c in text:
        depth += (c == "(") - (c == ")")
        if depth < 0:
            return False
    return depth == 0


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    return repr(value)


def model_file(instance: Instance, posed: Posed, undefined: set[str]) -> str:
    """The model file of one instance (the PRISM file by absolute path)."""
    lines = [f"name = {json.dumps(instance.name)}", f"spec = {json.dumps(posed.spec)}"]
    if posed.objective == "min":
        lines.append('objective = "min"')
    lines += ["", "[prism]", f"file = {json.dumps(str(instance.prism.resolve()))}"]
    given = {k: v for k, v in instance.constants.items() if k in undefined}
    if given:
        body = ", ".join(f"{k} = {_toml_value(v)}" for k, v in given.items())
        lines.append(f"constants = {{ {body} }}")
    if posed.labels:
        lines += ["", "[labels]"] + [f"{k} = {json.dumps(v)}" for k, v in posed.labels.items()]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- running


DRIVER = r"""
import json, sys, time
from mitld_lp import load_model, synthesize
from mitld_lp.model import ModelError
start = time.perf_counter()
try:
    model = load_model(sys.argv[1], max_states=int(sys.argv[2]))
except ModelError as exc:
    print(json.dumps({"error": str(exc)}))
    raise SystemExit(0)
loaded = time.perf_counter()
r = synthesize(model)
done = time.perf_counter()
exact = None
if sys.argv[3] == "exact":  # the exact answer, or why there is none
    from mitld_lp.exact.errors import ExactError, ExactTooLarge
    from mitld_lp.problem import ProblemError
    try:
        e = synthesize(model, exact=True).exact
        exact = "time limit" if e is None else [str(e.lower), str(e.upper)]
    except (ExactError, ExactTooLarge, ProblemError) as exc:
        exact = str(exc).splitlines()[0]
print(json.dumps({"lower": r.lower, "upper": r.upper, "certified": r.certified,
                  "status": str(r.status), "world": model.game.n_states,
                  "decided": getattr(model.game, "decided", 0),
                  "load": loaded - start, "solve": done - loaded, "exact": exact}))
"""


def ours(path: Path, max_states: int, timeout: float, exact: bool = False) -> dict[str, Any]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    try:
        run = subprocess.run([sys.executable, "-c", DRIVER, str(path), str(max_states),
                              "exact" if exact else "float"],
                             capture_output=True, text=True, timeout=timeout, env=env)
    except subprocess.TimeoutExpired:
        return {"error": f"over {timeout:g} s"}
    lines = run.stdout.strip().splitlines()
    if run.returncode != 0 or not lines:
        tail = (run.stderr.strip().splitlines() or ["no output"])[-1]
        return {"error": f"exit {run.returncode}: {tail[:200]}"}
    return json.loads(lines[-1])


def storm(instance: Instance, text: str) -> tuple[float, float]:
    """Storm's value and seconds (parse, build with the property, check)."""
    import stormpy

    start = time.perf_counter()
    program = stormpy.parse_prism_program(str(instance.prism))
    undefined = {c.name for c in program.constants if not c.defined}
    given = {k: v for k, v in instance.constants.items() if k in undefined}
    if given:
        program, _ = stormpy.instantiate_constants(program, given)
    others = {k: v for k, v in instance.constants.items() if k not in undefined}
    for name, value in others.items():  # the properties file's own constants
        shown = str(value).lower() if isinstance(value, bool) else str(value)
        text = re.sub(rf"(?<![\w\"]){re.escape(name)}(?![\w\"])", shown, text)
    props = stormpy.parse_properties(text, program)
    model = stormpy.build_model(program, props)
    result = stormpy.model_checking(model, props[0])
    value = float(result.get_value_vector()[model.initial_states[0]])
    return value, time.perf_counter() - start


def _labels_of(instance: Instance) -> tuple[dict[str, str], set[str]]:
    import stormpy

    program = stormpy.parse_prism_program(str(instance.prism))
    labels = {lab.name: str(lab.expression) for lab in program.labels}
    return labels, {c.name for c in program.constants if not c.defined}


def _fmt(x: float) -> str:
    return f"{x:.9g}"


def inside_exactly(lower: float, upper: float, reference: Fraction) -> bool:
    """Whether ``reference`` lies in ``[lower, upper]``, the two floats read as the
    rationals they are: no tolerance."""
    if not (math.isfinite(lower) and math.isfinite(upper)):
        return False
    return Fraction(lower) <= reference <= Fraction(upper)


def miss(lower: float, upper: float, reference: Fraction) -> str:
    """How far outside ``[lower, upper]`` the reference is, relative to it ("" inside)."""
    if inside_exactly(lower, upper, reference) or not (math.isfinite(lower)
                                                       and math.isfinite(upper)):
        return ""
    gap = Fraction(lower) - reference if Fraction(lower) > reference else reference - Fraction(
        upper)
    return f"{float(gap / reference):.1e}" if reference else f"{float(gap):.1e} (abs)"


def exact_verdict(exact: Any, reference: Fraction | float) -> str:
    """``--exact``: "yes" when the exact answer is QVBS's fraction (both truncation
    models' optima equal to it), "NO" when it is another, else why there is none."""
    if exact is None:
        return "-"
    if isinstance(exact, str):
        return f"none: {exact[:60]}"
    low, high = (Fraction(x) for x in exact)
    if not isinstance(reference, Fraction):
        return f"{float(low)!r}" + ("" if low == high else f"..{float(high)!r}") + " (approx ref)"
    return "yes" if low == high == reference else "NO"


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, required=True,
                    help="the benchmarks/ folder of a checkout of github.com/ahartmanns/qcomp")
    ap.add_argument("--max-states", type=int, default=2_000_000,
                    help="largest instance (QVBS's state count) to run (default 2,000,000)")
    ap.add_argument("--timeout", type=float, default=None,
                    help="seconds per instance for our solve (default 3600, --quick 120)")
    ap.add_argument("--family", action="append", help="only these families (repeatable)")
    ap.add_argument("--all", action="store_true",
                    help="every property of every family (PRISM and JANI; probabilities, "
                         "rewards, qualitative) through the door, per class: answered, "
                         "refused with the reason, inside the reference (qvbs_all.md/.csv)")
    ap.add_argument("--max-memory", default="4G",
                    help="--all: the door's --max-memory per property (default 4G)")
    ap.add_argument("--exact", action="store_true",
                    help="also each instance's exact optimum (solve --exact), compared with "
                         "QVBS's fraction")
    args = ap.parse_args(argv)
    if not (args.qvbs / "mdp").is_dir():
        ap.error(f"--qvbs {args.qvbs}: no mdp/ folder (give qcomp's benchmarks/ folder)")
    limit = min(args.max_states, QUICK_STATES) if args.quick else args.max_states
    timeout = args.timeout or (120.0 if args.quick else 3600.0)
    out = out_dir(args)
    if args.all:
        limit = min(args.max_states, ALL_QUICK_STATES) if args.quick else args.max_states
        shown = " ".join(["python experiments/qvbs.py --qvbs QVBS --all",
                          *(["--quick"] if args.quick else []), f"--max-states {limit}",
                          f"--timeout {timeout:g}", f"--max-memory {args.max_memory}",
                          *[f"--family {f}" for f in args.family or []]])
        head = ("## Every QVBS MDP property through the door\n\n"
                f"`{shown}` (QVBS: the benchmarks/ folder of a qcomp checkout; "
                f"{time.strftime('%Y-%m-%d')}). Each row is `mitld-lp solve FILE --prop "
                "... --const ... --json` in a child process; see experiments/qvbs_door.py.")
        return main_all(args.qvbs, out, limit, timeout, args.max_memory, args.family, head)
    work = out / "qvbs-models"
    work.mkdir(parents=True, exist_ok=True)

    runs, skipped = find_instances(args.qvbs, limit)
    if args.family:
        runs = [r for r in runs if r.family in args.family]
    header = ["instance", "states", "explored", "lower", "upper", "reference", "inside",
              "miss", "ours s", "storm s", "ratio", "storm value"]
    if args.exact:
        header.append("exact = ref")
    rows: list[list[Any]] = []
    trivial: list[list[Any]] = []
    outside: list[str] = []
    approximate: list[str] = []
    wrong: list[str] = []
    widths: list[float] = []
    for inst in runs:
        missing = [f.name for f in (inst.prism, inst.props) if not f.is_file()]
        if missing:
            skipped.append((inst.name, f"missing from the checkout: {', '.join(missing)}"))
            continue
        texts = read_properties(inst.props)
        if inst.prop not in texts:
            skipped.append((inst.name, f"property not in {inst.props.name}"))
            continue
        labels, undefined = _labels_of(inst)
        try:
            posed = pose(texts[inst.prop], labels, inst.constants)
        except NotPosed as exc:
            skipped.append((inst.name, str(exc)))
            continue
        path = work / f"{inst.name}.toml"
        path.write_text(model_file(inst, posed, undefined), encoding="utf-8")
        got = ours(path, max(limit, inst.qvbs_states), timeout, args.exact)
        if "error" in got:
            reason = got["error"]
            skipped.append((inst.name, reason))
            continue
        value, storm_seconds = storm(inst, texts[inst.prop])
        ref = float(inst.reference)
        exact_ref = isinstance(inst.reference, Fraction)
        reference = inst.reference if exact_ref else Fraction(ref)
        lower, upper = got["lower"], got["upper"]
        inside = got["certified"] and inside_exactly(lower, upper, reference)
        if not exact_ref:
            approximate.append(inst.name)
        elif not inside:
            outside.append(inst.name)
        widths.append(upper - lower)
        seconds = got["load"] + got["solve"]
        easy = ref <= TRIVIAL or ref >= 1 - TRIVIAL
        said = ("yes" if inside else "NO") if exact_ref else (
            "approx yes" if inside else "approx no")
        row = [inst.name, f"{inst.qvbs_states:,}", f"{got['world']:,}", repr(lower),
               repr(upper), repr(ref), said, miss(lower, upper, reference) if got["certified"]
               else "uncertified", f"{seconds:.2f}", f"{storm_seconds:.2f}",
               "-" if easy else f"{seconds / storm_seconds:.1f}", _fmt(value)]
        if args.exact:
            verdict = exact_verdict(got.get("exact"), inst.reference)
            if verdict == "NO":
                wrong.append(inst.name)
            row.append(verdict)
        (trivial if easy else rows).append(row)
        print(f"{inst.name}: [{lower!r}, {upper!r}] ref {ref!r} "
              f"{said if exact_ref else said.upper()} ({seconds:.2f} s, Storm "
              f"{storm_seconds:.2f} s)" + (f" exact {row[-1]}" if args.exact else ""),
              flush=True)

    report = ["## QVBS PRISM MDPs through the front door", ""]
    if rows:
        report += [text_table(header, rows), ""]
    if trivial:
        report += ["Trivial references (0, 1, < 1e-3 or > 1 - 1e-3; no ratio):", "",
                   text_table(header, trivial), ""]
    ratios = [float(r[10]) for r in rows]
    run = len(rows) + len(trivial)
    exact_run = run - len(approximate)
    report.append(f"{run} run, {exact_run} with an exact reference: "
                  f"{exact_run - len(outside)} inside the certified bracket exactly, "
                  f"{len(outside)} outside{': ' + ', '.join(outside) if outside else ''}; "
                  f"{len(approximate)} with an approximate reference (not counted); "
                  f"largest bracket width {max(widths, default=0.0):.3g}")
    if args.exact:
        agree = sum(1 for r in rows + trivial if r[-1] == "yes")
        report.append(f"exact answers: {agree} equal to QVBS's fraction, {len(wrong)} not"
                      f"{': ' + ', '.join(wrong) if wrong else ''}; the others have none "
                      "(refused, past the budget) or an approximate reference")
    if ratios:
        report.append("ours / Storm time (non-trivial): median "
                      f"{sorted(ratios)[len(ratios) // 2]:.1f}, geometric mean "
                      f"{math.exp(sum(math.log(max(r, 1e-3)) for r in ratios) / len(ratios)):.1f}")
    report += ["", f"Not run ({len(skipped)}):"] + [f"  {what}: {why}" for what, why in skipped]
    text = "\n".join(report)
    print(text)
    write_csv(out / "qvbs.csv", header, rows + trivial)
    write_text(out / "qvbs.md", markdown_table(header, rows + trivial) + "\n" + "\n".join(
        f"- not run: {what}: {why}" for what, why in skipped) + "\n")
    return 1 if outside or wrong else 0


if __name__ == "__main__":
    raise SystemExit(main())

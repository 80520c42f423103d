"""Check: the command line's start-up changes no answer, on every bundled model.

The command line imports SciPy and lark in its own way (``mitld_lp.startup``: SciPy's
array-API layer without NumPy's unused submodules, lark without ``regex``).  This
script solves every ``models/*.toml`` three ways, each in a fresh process, and prints
each status and certified ``[lower, upper]`` beside its CPU seconds:

* ``command``: ``python -m mitld_lp solve MODEL --json -q`` (the console script's route);
* ``library``: ``synthesize(load_model(MODEL))`` in a plain interpreter, which imports
  SciPy and lark as any program does;
* ``base`` (with ``--compare BASE``): the command line with another ``mitld_lp``, a
  checkout's folder or a commit of this repository (``git archive``), e.g. the one
  before the start-up work.

Every row's status and both ends must be equal (as floats, no tolerance), or the run
stops with the rows that differ.  ``--quick`` solves two models (the bundled case and
one with a fitted law, whose fit imports ``scipy.optimize`` and ``scipy.stats`` through
the layer) into ``experiments/out/quick``::

    python experiments/startup_answers.py --compare e1d68a4 --out experiments/results
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import _common  # noqa: E402
from bench_startup import base_checkout, run_cpu  # noqa: E402

QUICK = ("bus_grid.toml", "bus_fit.toml")

LIBRARY = """
import json, sys
from mitld_lp import load_model, synthesize
r = synthesize(load_model(sys.argv[1]))
print(json.dumps(dict(status=str(r.status), lower=r.lower, upper=r.upper)))
"""


def answer(out: str) -> tuple[str, float, float]:
    """Status, lower and upper of a JSON answer (the command's or the library's)."""
    d = json.loads(out.strip().splitlines()[-1])
    return str(d["status"]), float(d["lower"]), float(d["upper"])


def ways(model: Path, compare: Path | None) -> dict[str, tuple[list[str], Path | None]]:
    py = sys.executable
    command = [py, "-m", "mitld_lp", "solve", str(model), "--json", "-q"]
    out = {"command": (command, None), "library": ([py, "-c", LIBRARY, str(model)], None)}
    if compare is not None:
        out["base"] = (command, compare)
    return out


def main(argv: list[str] | None = None) -> list[list[Any]]:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--compare", default=None, metavar="BASE",
                    help="also solve with this checkout's (a folder) or this commit's "
                         "mitld_lp (the base rows)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        base = None if args.compare is None else base_checkout(args.compare, Path(tmp))
        return solve_all(args, base)


def solve_all(args: Any, base: Path | None) -> list[list[Any]]:
    """Every model (two with ``--quick``) in every way; the table written and said."""
    out = _common.out_dir(args)
    models = ([_common.MODELS / m for m in QUICK] if args.quick
              else sorted(_common.MODELS.glob("*.toml")))
    header = ["model", "way", "status", "lower", "upper", "CPU (s)"]
    rows: list[list[Any]] = []
    differ: list[str] = []
    for model in models:
        seen: dict[str, tuple[str, float, float]] = {}
        for way, (cmd, code) in ways(model, base).items():
            cpu, text = run_cpu(cmd, code)
            seen[way] = answer(text)
            status, lower, upper = seen[way]
            rows.append([model.name, way, status, repr(lower), repr(upper), f"{cpu:.3f}"])
            print(_common.text_table(header, rows[-1:]).splitlines()[-1], flush=True)
        if len(set(seen.values())) != 1:
            differ.append(f"{model.name}: {seen}")
    text = _common.markdown_table(header, rows)
    verdict = (f"{len(models)} models, {len(rows) // len(models)} ways each: "
               + ("the same status and bracket in every way" if not differ
                  else f"{len(differ)} models differ"))
    if args.compare is not None:
        verdict += f"; `base`: the mitld_lp of {args.compare}"
    _common.write_csv(out / "startup_answers.csv", header, rows)
    _common.write_text(out / "startup_answers.md", text + "\n" + verdict + "\n")
    print(verdict)
    print(f"wrote {_common.shown(out / 'startup_answers.md')}")
    if differ:
        raise SystemExit("answers differ:\n" + "\n".join(differ))
    return rows


if __name__ == "__main__":
    main()

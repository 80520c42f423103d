"""Expected times through the door on QVBS's resource-gathering, ours beside Storm in the
same run: ``expsteps`` (``Tmin=? [F "success"]``) by the float route (a certified
bracket) and under ``--exact`` (the optimum as a fraction), and the bound
``Tmin<=b [F "success"]`` with ``b`` just above and just below the optimum, each with its
seconds (the whole ``mitld-lp solve`` process: Storm's build and our solve); Storm's
default engine and its exact engine on its own build of the same file, value and
seconds (build and check).

    python experiments/door_times.py --qvbs BENCHMARKS/mdp/resource-gathering  # 200-15-15
    python experiments/door_times.py --qvbs BENCHMARKS/mdp/resource-gathering --quick  # 5-5

``--qvbs``: the resource-gathering folder of a checkout of the Quantitative Verification
Benchmark Set (its ``resource-gathering.pm``).  Writes ``door_times.md`` into the output
folder.  One run on a shared machine: the seconds are wall-clock.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from fractions import Fraction
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common  # noqa: E402

PROP = 'Tmin=? [F "success"]'


def storm(path: Path, constants: dict[str, int], exact: bool) -> tuple[str, float]:
    """Storm's value of ``PROP`` at the initial state (its exact engine when ``exact``)
    and its build + check seconds."""
    import stormpy

    t = time.perf_counter()
    program = stormpy.parse_prism_program(str(path))
    props = stormpy.parse_properties(PROP, program)
    program, props = stormpy.instantiate_constants(program, constants, props)
    if exact:
        model = stormpy.build_model[stormpy.Rational](program, props)
        env = stormpy.Environment()
        env.solver().force_exact = True
    else:
        model = stormpy.build_model(program, props)
        env = stormpy.Environment()
    result = stormpy.model_checking(model, props[0], environment=env,
                                    only_initial_states=True)
    return str(result.get_value(model.initial_states[0])), time.perf_counter() - t


def ours(path: Path, constants: dict[str, int], prop: str, *extra: str) -> tuple[dict, float]:
    """``mitld-lp solve PATH --prop PROP --const ... --json`` as a user runs it: its
    answer and the process's seconds."""
    root = Path(__file__).resolve().parent.parent
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(root), *filter(None, [os.environ.get("PYTHONPATH")])])}
    const = ",".join(f"{k}={v}" for k, v in constants.items())
    t = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "mitld_lp", "solve", str(path), "--prop",
                           prop, "--const", const, "--json", "-q", *extra],
                          capture_output=True, text=True, env=env, check=False)
    seconds = time.perf_counter() - t
    if not done.stdout.strip():
        raise SystemExit(f"mitld-lp failed ({done.returncode}): {done.stderr.strip()}")
    return json.loads(done.stdout), seconds


def main(argv: list[str] | None = None) -> None:
    ap = _common.parser(__doc__.split("\n")[0])
    ap.add_argument("--qvbs", type=Path, required=True,
                    help="the resource-gathering folder of a QVBS checkout")
    args = ap.parse_args(argv)
    out = _common.out_dir(args)
    path = args.qvbs / "resource-gathering.pm"
    gold = 5 if args.quick else 15
    constants = {"B": 200, "GOLD_TO_COLLECT": gold, "GEM_TO_COLLECT": gold}
    instance = f"resource-gathering {200}-{gold}-{gold}"
    lines = [f"{instance}, `{PROP}`", "",
             "| run | answer | states | seconds |", "|---|---|---|---|"]

    def row(run: str, answer: str, states: str, seconds: float) -> None:
        line = f"| {run} | {answer} | {states} | {seconds:.2f} |"
        print(line, flush=True)
        lines.append(line)

    fast, seconds = ours(path, constants, PROP)
    row("ours, float route", f"[{fast['lower']!r}, {fast['upper']!r}]"
        + ("" if fast["certified"] else " NOT certified"), f"{fast['states']:,}", seconds)
    exact, seconds = ours(path, constants, PROP, "--exact")
    row("ours, --exact", f"{exact['value']}", f"{exact['states']:,}", seconds)
    value, seconds = storm(path, constants, exact=False)
    row("Storm, default engine", value, "", seconds)
    value, seconds = storm(path, constants, exact=True)
    row("Storm, exact engine", value, "", seconds)
    optimum = Fraction(exact["value"])
    for b in (optimum + Fraction(1, 10), optimum - Fraction(1, 10)):
        bound = f'Tmin<={b.numerator}/{b.denominator} [F "success"]'
        answer, seconds = ours(path, constants, bound)
        row(f"ours, `{bound}`", f"{answer['verdict']}", f"{answer['states']:,}", seconds)
    _common.write_text(out / "door_times.md", "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()

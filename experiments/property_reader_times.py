"""What reading a property costs the door, ours beside Storm's reader, in one run.

    python experiments/property_reader_times.py --qvbs <QVBS> --compare <base>
    python experiments/property_reader_times.py --qvbs <QVBS> --quick

Per QVBS instance and property (CPU seconds, the routes taking turns, ``--repeats``):

* ``read storm`` / ``read ours``: the property part alone in a process that has already
  imported stormpy and parsed the program (as the door has): Storm's reader
  (``stormpy.parse_properties``, the constants put in, the task posed) against ours
  (:func:`mitld_lp.worlds.property_own.read_any`, its modules' import included);
* ``door``: the whole ``mitld-lp solve MODEL --prop TEXT --const ... --json`` process of
  this checkout, and of ``--compare BASE`` (a checkout of the base), with the answer;
* ``storm``: a stormpy script doing Storm's whole run (import, parse, build, sound check).

Writes ``property_reader_times.md`` into the output folder (``--out``; by default the
scratch folder ``experiments/out/quick``).
"""

from __future__ import annotations

import json
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common  # noqa: E402
from bench_startup import run_cpu  # noqa: E402

# (family folder, model file, constants, property)
CASES = [
    ("zeroconf", "zeroconf.prism", "N=20,K=2,reset=true", 'Pmax=? [ F (l=4 & ip=1) ]'),
    ("consensus", "consensus.2.prism", "K=2",
     'Pmin=? [ F "finished"&"all_coins_equal_1" ]'),
    ("csma", "csma.2-2.prism", "", 'Pmax=? [ !"collision_max_backoff" U "all_delivered" ]'),
]

PART = r"""
import sys, time
from mitld_lp.worlds.properties import parse_constants, pick, pose_property, read_program
program = read_program(sys.argv[1], storm=True)  # Storm's program, as the base door read it
constants = parse_constants(sys.argv[2])
ours = sys.argv[4] == "ours"
start = time.process_time()
if ours:
    from mitld_lp.worlds.property_own import read_any
    props = read_any(program, sys.argv[3], "--prop", constants)
else:
    from mitld_lp.worlds.properties import read_properties
    props = read_properties(program.program, sys.argv[3], "--prop", constants)
(name, prop), = pick(props, None, "--prop")
query = pose_property(name, prop, program.labels, program.reserved, chain=program.chain)
print(time.process_time() - start, type(prop).__name__, query.spec)
"""

STORM = r"""
import sys
import stormpy
program = stormpy.parse_prism_program(sys.argv[1])
props = stormpy.parse_properties(sys.argv[3], program)
given = {}
for item in filter(None, sys.argv[2].split(",")):
    k, v = item.split("=")
    given[k] = v == "true" if v in ("true", "false") else int(v)
program, props = stormpy.instantiate_constants(program, given, props)
model = stormpy.build_model(program, props)
env = stormpy.Environment()
env.solver().force_soundness = True
result = stormpy.model_checking(model, props[0], environment=env)
print(result.get_value(model.initial_states[0]))
"""


def door(code: Path, model: Path, constants: str, prop: str) -> tuple[float, str]:
    argv = [sys.executable, "-m", "mitld_lp", "solve", str(model), "--prop", prop, "--json"]
    if constants:
        argv += ["--const", constants]
    seconds, out = run_cpu(argv, code)
    answer = json.loads(out.strip().splitlines()[-1])
    return seconds, f"[{answer['lower']}, {answer['upper']}]"


def main(argv: list[str] | None = None) -> int:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, required=True, help="the QVBS benchmarks folder")
    ap.add_argument("--compare", type=Path, default=None, help="a checkout of the base")
    ap.add_argument("--repeats", type=int, default=None)
    args = ap.parse_args(argv)
    if args.out is None:  # a scratch folder, never the committed results
        args.out = _common.QUICK_OUT
    out = _common.out_dir(args)
    repeats = args.repeats or (1 if args.quick else 3)
    cases = CASES[:1] if args.quick else CASES
    rows = []
    for family, name, constants, prop in cases:
        model = args.qvbs / "mdp" / family / name
        runs: dict[str, list[float]] = {}
        answers: dict[str, str] = {}
        for _ in range(repeats):
            for route in ("storm", "ours"):
                _, text = run_cpu([sys.executable, "-c", PART, str(model), constants, prop,
                                   route], _common.ROOT)
                seconds, kind, spec = text.split(maxsplit=2)
                runs.setdefault(f"read {route}", []).append(float(seconds))
                answers[f"read {route}"] = f"{kind}: {spec.strip()}"
            for label, code in (("door", _common.ROOT), ("door base", args.compare)):
                if code is None:
                    continue
                seconds, answer = door(code, model, constants, prop)
                runs.setdefault(label, []).append(seconds)
                answers[label] = answer
            seconds, text = run_cpu([sys.executable, "-c", STORM, str(model), constants,
                                     prop], _common.ROOT)
            runs.setdefault("storm", []).append(seconds)
            answers["storm"] = text.strip()
        for label, values in runs.items():
            rows.append((f"{family} {name} {constants}", label,
                         f"{statistics.median(values):.4f}", f"{min(values):.4f}",
                         answers[label]))
    header = ("instance", "route", "median CPU s", "least CPU s", "answer")
    print(_common.text_table(header, rows))
    _common.write_text(out / "property_reader_times.md", _common.markdown_table(header, rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

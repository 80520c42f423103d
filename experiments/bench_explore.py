"""Benchmark: a bounded task on a huge PRISM world costs what its product costs.

The world is an N x N grid written in PRISM by this script (four moves that slip with
probability 1/10; ``goal`` at (4, 3)), the task ``F[0,10] goal`` from (0, 0).  Each
route runs as a process of its own (imports included), with its answer, CPU seconds
(the process and any child it waits for) and peak resident memory:

* ``ours auto``: a model file (``[prism] file``, the spec) through :func:`mitld_lp.load_model`
  and :func:`mitld_lp.synthesize`, as the command line runs it: the world explored up to
  the task's horizon (``explore = "auto"``, :class:`mitld_lp.worlds.prism.LazyPrismGame`);
* ``ours full``: the same with ``[prism] explore = "full"``: every reachable state built
  before the product (the behaviour before);
* ``small``: ``ours auto`` on a 12 x 12 grid, whose product is the same (every state
  within 10 moves of (0, 0) has the same moves there): the target is ``ours auto`` on the
  big grid within 2x of it;
* ``storm``: stormpy parses the file, builds it (Storm's sparse engine) and checks
  ``Pmax=? [F<=10 "goal"]``, the peer in the same run.

Every route must give the same value: ours the same certified bracket bit for bit (the
script exits 1 otherwise), Storm's value inside it within 1e-9.

With ``--qvbs DIR`` (a checkout's ``benchmarks/`` folder, read only) QVBS's
resource-gathering 200-15-15 ``prgoldgem`` (``Pmax=? [F<=200 "success"]``, as
``F[0,200] success``) runs the same three routes: its 23,971 states are all within 200
moves, so ``auto`` explores the whole world and reads it as a table, as ``full`` does.

    python experiments/bench_explore.py --out experiments/results   # N = 2001, 4,004,001 states
    python experiments/bench_explore.py --quick                     # N = 201, to the scratch folder

Written: ``bench_explore.csv`` and ``bench_explore.md``.
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import _common  # noqa: E402

SPEC = "F[0,10] goal"
STORM_PROPERTY = 'Pmax=? [F<=10 "goal"]'  # SPEC as Storm reads it on the PRISM file
SMALL = 12
RESOURCE = ("resource-gathering", {"B": 200, "GOLD_TO_COLLECT": 15, "GEM_TO_COLLECT": 15},
            "F[0,200] success", 'Pmax=? [F<=200 "success"]')


def grid_prism(n: int) -> str:
    """An n x n grid in PRISM: four moves, each staying put with probability 1/10."""
    return f"""mdp
const int N = {n - 1};
module robot
  x : [0..N] init 0;
  y : [0..N] init 0;
  [east]  x<N -> 0.9:(x'=x+1) + 0.1:(x'=x);
  [west]  x>0 -> 0.9:(x'=x-1) + 0.1:(x'=x);
  [north] y<N -> 0.9:(y'=y+1) + 0.1:(y'=y);
  [south] y>0 -> 0.9:(y'=y-1) + 0.1:(y'=y);
endmodule
label "goal" = x=4 & y=3;
"""


def model_text(prism: Path, spec: str, explore: str, constants: dict[str, int]) -> str:
    lines = [f'name = "{prism.stem}"', f'spec = "{spec}"', "", "[prism]",
             f'file = "{prism.as_posix()}"', f'explore = "{explore}"']
    if constants:
        lines.append("constants = { " + ", ".join(f"{k} = {v}" for k, v in constants.items())
                     + " }")
    return "\n".join(lines) + "\n"


def write_grid(folder: Path, n: int, explore: str = "auto") -> tuple[Path, Path]:
    """The n x n grid's PRISM file (``grid<n>.prism``) and its model file (the task
    :data:`SPEC` from that file, explored as ``explore`` says) written in ``folder``."""
    prism = _common.write_text(folder / f"grid{n}.prism", grid_prism(n))
    model = _common.write_text(folder / f"grid{n}_{explore}.toml",
                               model_text(prism, SPEC, explore, {}))
    return prism, model


def _usage() -> tuple[float, int]:
    """CPU seconds of this process and its waited-for children; peak resident bytes."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime
    return cpu, max(me.ru_maxrss, kids.ru_maxrss) * 1024


def child_ours(model: str) -> dict[str, Any]:
    import mitld_lp

    m = mitld_lp.load_model(model)
    r = mitld_lp.synthesize(m)
    return {"lower": r.lower, "upper": r.upper, "certified": r.certified,
            "product": r.mdp.n_states, "explored": m.game.explored}


def child_storm(prism: str, constants: dict[str, int], prop: str) -> dict[str, Any]:
    import stormpy

    program = stormpy.parse_prism_program(prism)
    if constants:
        program, _ = stormpy.instantiate_constants(program, constants)
    props = stormpy.parse_properties(prop, program)
    model = stormpy.build_model(program, props)
    result = stormpy.model_checking(model, props[0], only_initial_states=True)
    return {"value": float(result.get_value(model.initial_states[0])),
            "explored": model.nr_states}


def run_child(kind: str, *args: str, timeout: float) -> dict[str, Any]:
    """One route in a process of its own: its answer, CPU seconds and peak memory."""
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, __file__, "--child", kind, *args],
                          capture_output=True, text=True, timeout=timeout)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"{kind} {args}: failed\n{done.stderr[-2000:]}")
    record = json.loads(done.stdout.strip().splitlines()[-1])
    record["wall"] = wall
    return record


def _child_main(argv: list[str]) -> None:
    kind, *rest = argv
    if kind == "ours":
        out = child_ours(rest[0])
    else:
        out = child_storm(rest[0], json.loads(rest[1]), rest[2])
    cpu, peak = _usage()
    out.update(cpu=cpu, peak=peak)
    print(json.dumps(out))


def _row(case: str, route: str, states: str, r: dict[str, Any]) -> list[Any]:
    value = (f"[{r['lower']!r}, {r['upper']!r}]" if "lower" in r else repr(r["value"]))
    return [case, route, states, r["explored"], r.get("product", ""), value,
            f"{r['cpu']:.2f}", f"{r['wall']:.2f}", f"{r['peak'] / 2**20:.0f}"]


def main(argv: list[str] | None = None) -> int:
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--child":
        _child_main(sys.argv[2:])
        return 0
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=None,
                    help="the big grid's side (default 2001; --quick 201)")
    ap.add_argument("--qvbs", type=Path, default=None,
                    help="a QVBS checkout's benchmarks/ folder: also resource-gathering")
    args = ap.parse_args(argv)
    out = _common.out_dir(args)
    n = args.n or (201 if args.quick else 2001)
    timeout = 600.0 if args.quick else 3600.0
    header = ["case", "route", "world states", "explored", "product", "answer", "cpu s",
              "wall s", "peak MB"]
    rows: list[list[Any]] = []
    failures: list[str] = []

    grids = {}
    results: dict[str, dict[str, Any]] = {}
    for key, side, explore in (("auto", n, "auto"), ("full", n, "full"),
                               ("small", SMALL, "auto")):
        grids[side], model = write_grid(out, side, explore)
        results[key] = run_child("ours", str(model), timeout=timeout)
    results["storm"] = run_child("storm", str(grids[n]), "{}", STORM_PROPERTY,
                                 timeout=timeout)
    big = f"{n * n:,}"
    for key, label, states in (("small", f"ours auto ({SMALL}x{SMALL})", f"{SMALL * SMALL}"),
                               ("auto", "ours auto", big), ("full", "ours full", big),
                               ("storm", "storm", big)):
        rows.append(_row(f"grid {n}x{n} {SPEC}", label, states, results[key]))
    ours = [(results[k]["lower"], results[k]["upper"], results[k]["product"])
            for k in ("auto", "full", "small")]
    if len(set(ours)) != 1:
        failures.append(f"grid: the brackets or products differ: {ours}")
    lower, upper, _ = ours[0]
    if not lower - 1e-9 <= results["storm"]["value"] <= upper + 1e-9:
        failures.append(f"grid: Storm's {results['storm']['value']} outside [{lower}, {upper}]")
    ratio = results["auto"]["cpu"] / results["small"]["cpu"]
    notes = [f"grid {n}x{n}: auto / small-grid CPU = {ratio:.2f} (target <= 2); "
             f"full / auto CPU = {results['full']['cpu'] / results['auto']['cpu']:.1f}; "
             f"storm / auto CPU = {results['storm']['cpu'] / results['auto']['cpu']:.1f}"]

    if args.qvbs is not None:
        family, constants, spec, prop = RESOURCE
        prism = args.qvbs / "mdp" / family / f"{family}.pm"
        if not prism.is_file():
            failures.append(f"--qvbs {args.qvbs}: no {prism}")
        else:
            rg: dict[str, dict[str, Any]] = {}
            for explore in ("auto", "full"):
                model = _common.write_text(out / f"{family}_{explore}.toml",
                                           model_text(prism.resolve(), spec, explore, constants))
                rg[explore] = run_child("ours", str(model), timeout=timeout)
            rg["storm"] = run_child("storm", str(prism), json.dumps(constants), prop,
                                    timeout=timeout)
            case = f"{family} 200-15-15 {spec}"
            for key in ("auto", "full", "storm"):
                rows.append(_row(case, "storm" if key == "storm" else f"ours {key}",
                                 f"{rg['storm']['explored']:,}", rg[key]))
            if (rg["auto"]["lower"], rg["auto"]["upper"]) != (rg["full"]["lower"],
                                                              rg["full"]["upper"]):
                failures.append(f"{family}: auto and full brackets differ")
            notes.append(f"{family}: auto / full CPU = "
                         f"{rg['auto']['cpu'] / rg['full']['cpu']:.2f}; "
                         f"auto / storm CPU = {rg['auto']['cpu'] / rg['storm']['cpu']:.1f}")

    print(_common.text_table(header, rows))
    for line in notes + failures:
        print(line)
    _common.write_csv(out / "bench_explore.csv", header, rows)
    _common.write_text(out / "bench_explore.md", _common.markdown_table(header, rows)
                       + "\n" + "\n".join(f"- {x}" for x in notes + failures) + "\n")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())

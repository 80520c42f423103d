"""Constraints on risk and time (issue 19) on the bus case with a puddle.

``models/bus_risk.toml``: the bus world of ``models/bus_grid.toml`` with two puddle
cells on the bottom row (the direct way to station B).  Printed and written:

1. the best success probability under a risk bound ``P(F puddle) <= r`` for several
   ``r``, each certified, beside Storm's multi-objective value on the DRN of the same
   merged model (their difference) and both tools' seconds (wall and CPU);
2. the curve of success probability against a bound on the expected steps until the
   task is decided, with the risk bound 0.05 (``pareto``: certified points only);
3. the fastest optimal policy (``--then min-steps``) against the optimal one.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import _common

from mitld_lp.model import loads_model
from mitld_lp.routes.constrained_export import write_merged_drn
from mitld_lp.synthesis import synthesize_constrained
from mitld_lp.tradeoff import pareto, plot
from mitld_lp.tradeoff import write_csv as write_pareto_csv

RISK = 0.05


def _clock():
    return time.perf_counter(), time.process_time()


def _since(start):
    wall, cpu = _clock()
    return wall - start[0], cpu - start[1]


def _storm(drn: Path, query: str) -> tuple[float, float, float]:
    import stormpy
    import stormpy.environments as env_mod

    t = _clock()
    model = stormpy.build_model_from_drn(str(drn))
    env = stormpy.Environment()
    multi = env.modelchecker().multi()
    multi.precision = stormpy.Rational("1/1000000000")
    multi.precision_type = env_mod.MultiObjectivePrecisionType.ABSOLUTE
    prop = stormpy.parse_properties(query)[0]
    value = stormpy.model_checking(model, prop, environment=env).get_value(
        model.initial_states[0])
    return (value, *_since(t))


def main(argv: list[str] | None = None):
    args = _common.parser(__doc__.splitlines()[0]).parse_args(argv)
    out = _common.out_dir(args)
    path = _common.model_path("bus_risk.toml")
    text = path.read_text(encoding="utf-8")
    model = loads_model(text, str(path))
    risks = [0.0, 0.05, 1.0] if args.quick else [0.0, 0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 1.0]
    rows = []
    print("1. best success probability under P(F puddle) <= r (certified), Storm's "
          "multi-objective value on the same model")
    print(f"{'r':>6} {'ours':>10} {'Storm':>10} {'|diff|':>9} {'risk used':>10} "
          f"{'random.':>7} {'ours s (cpu)':>13} {'Storm s (cpu)':>14}")
    for r in risks:
        t = _clock()
        res = synthesize_constrained(model, [f"P(F puddle) <= {r}"])
        wall, cpu = _since(t)
        drn = write_merged_drn(res.merged, out / "constraints_model.drn", overwrite=True)
        storm, s_wall, s_cpu = _storm(drn, f'multi(Pmax=? [F "target"], P<={r} [F "c1"])')
        drn.unlink()
        row = [r, res.lower, res.upper, storm, abs(res.lower - storm),
               res.constraints[0].value, res.summary()["randomized_states"], res.certified,
               wall, cpu, s_wall, s_cpu]
        rows.append(row)
        print(f"{r:6.3f} {res.lower:10.7f} {storm:10.7f} {row[4]:9.1e} {row[5]:10.6f} "
              f"{row[6]:7d} {wall:6.2f} ({cpu:4.2f}) {s_wall:7.2f} ({s_cpu:4.2f})"
              + ("" if res.certified else "  NOT certified"))
    _common.write_csv(out / "constraints_risk.csv",
                      ["risk_bound", "lower", "upper", "storm", "abs_diff", "risk_value",
                       "randomized_states", "certified", "wall_s", "cpu_s", "storm_wall_s",
                       "storm_cpu_s"], rows)

    print(f"\n2. success probability against E(steps) <= b, with P(F puddle) <= {RISK}")
    risky = loads_model(text.replace('spec = ', f'constraints = ["P(F puddle) <= {RISK}"]\n'
                                     'spec = ', 1), str(path))
    points = pareto(risky, "steps", 4 if args.quick else 12)
    write_pareto_csv(points, out / "constraints_steps.csv", overwrite=True)
    left = plot(points, out / "constraints_steps.png", "steps",
                f"bus with puddle, P(F puddle) <= {RISK}", overwrite=True)
    for p in points:
        print(f"  E(steps) <= {p.bound:7.4f}: [{p.lower:.6f}, {p.upper:.6f}] "
              f"({p.status}{'' if p.certified else ', not certified'})")
    print(f"  plotted {len(points) - left} certified points of {len(points)}")

    print("\n3. the fastest optimal policy")
    best = synthesize_constrained(risky)
    fast = synthesize_constrained(risky, then="min-steps")
    print(f"  optimal:           P = {best.lower:.7f}, E(steps) = {best.steps:.4f}")
    print(f"  then min-steps:    P = {fast.lower:.7f}, E(steps) = {fast.steps:.4f} "
          f"(tolerance 1e-6 on P)")
    return rows, points, (best, fast)


if __name__ == "__main__":
    sys.exit(0 if main() else 1)

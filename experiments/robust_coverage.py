"""Coverage of robust synthesis from data (issue 20) on the bus case.

Bus 2's arrival step follows geometric(0.3), the truth, which the robot does not know;
bus 1's law is known, geometric(0.8) (``models/bus_grid.toml``).  In each repetition:

1. N mornings are logged, each watched for a uniform 1..8 steps, so a bus that comes
   later is a censored observation;
2. bus 2's law is fitted with a 95% band (``fit_law``, the censored geometric closed form
   and its Clopper-Pearson interval);
3. the robust policy is synthesised (its certified robust lower bound: what it guarantees
   whatever law of the band the bus follows);
4. the policy is evaluated exactly under the true law.

Printed and written (``robust_coverage.csv``: one row per N; ``robust_coverage_runs.csv``:
one row per repetition; ``robust_coverage.png``): the fraction of repetitions whose band
holds the true p, the fraction whose true value is at least the robust lower bound
(which the band's coverage implies, so it is at least 0.95 up to sampling), the mean
robust bound against the true value of the robust policy and the true optimum, and, on
the first repetition of each N, Storm's robust value iteration on the exported interval
DRN (one ambiguous event per choice: the file is exact) with the seconds of both.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import _common
import numpy as np

from mitld_lp import Model, load_model, synthesize
from mitld_lp.distributions import geometric
from mitld_lp.distributions.fit import fit_law
from mitld_lp.product.imdp import IntervalMDP
from mitld_lp.routes.robust import RobustResult, robust_game
from mitld_lp.solvers.robust import robust_interval_iteration
from mitld_lp.solvers.robust_export import write_interval_drn

P_TRUE = 0.3
WATCH = 8
CONFIDENCE = 0.95


def _clock() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def _since(start: tuple[float, float]) -> tuple[float, float]:
    wall, cpu = _clock()
    return wall - start[0], cpu - start[1]


def value_under(result: RobustResult, hazard: float) -> float:
    """The robust policy's exact value when bus 2's hazard is ``hazard`` at every step
    (the band narrowed to that point: nature has no choice left)."""
    m = result.imdp
    fixed: IntervalMDP = replace(m, band_lo=np.full_like(m.band_lo, hazard),
                                 band_hi=np.full_like(m.band_hi, hazard))
    policy = np.where(result.lower_model.policy < 0,
                      np.asarray(m.row_groups[:-1]), result.lower_model.policy)
    game = robust_game(fixed).restrict(policy)
    it = robust_interval_iteration(game, m.target, tol=1e-12)
    return float(it.lower[m.initial])


def storm_value(drn: Path) -> tuple[float, float, float]:
    """Storm's robust value iteration (precision 1e-12) on the interval DRN, with its
    wall and CPU seconds (Storm's log kept off stdout)."""
    import stormpy

    from mitld_lp.worlds.prism_program import storm_quiet

    t = _clock()
    with storm_quiet():
        model = stormpy.build_model_from_drn[stormpy.Interval](str(drn))
        env = stormpy.Environment()
        env.solver().min_max().precision = stormpy.Rational("1/1000000000000")
        prop = stormpy.parse_properties('Pmax=? [F "target"]')[0]
        value = stormpy.model_checking(
            model, prop, uncertainty_resolution_mode=stormpy.UncertaintyResolutionMode.ROBUST,
            environment=env).get_value(model.initial_states[0])
    return (float(value), *_since(t))


def plot(rows: list[list[object]], optimum: float, path: Path) -> None:
    from matplotlib.figure import Figure

    n = np.array([r[0] for r in rows], dtype=float)
    fig = Figure(figsize=(9, 3.6), layout="constrained")
    ax, bx = fig.subplots(1, 2)
    ax.axhline(optimum, color="k", lw=1, label="true optimum")
    ax.plot(n, [r[5] for r in rows], "o-", label="true value of the robust policy")
    ax.plot(n, [r[4] for r in rows], "s-", label="robust lower bound (mean)")
    ax.fill_between(n, [r[6] for r in rows], [r[7] for r in rows], alpha=0.2,
                    label="robust bound, 10-90%")
    ax.set_xscale("log")
    ax.set_xlabel("logged mornings N")
    ax.set_ylabel("P(catch a bus)")
    ax.legend(fontsize=8, loc="lower right")
    bx.axhline(CONFIDENCE, color="k", lw=1, ls="--", label=f"{CONFIDENCE:.0%}")
    bx.plot(n, [r[2] for r in rows], "o-", label="band holds true p")
    bx.plot(n, [r[3] for r in rows], "s-", label="true value >= robust bound")
    bx.set_xscale("log")
    bx.set_ylim(0.8, 1.01)
    bx.set_xlabel("logged mornings N")
    bx.set_ylabel("fraction of repetitions")
    bx.legend(fontsize=8, loc="lower right")
    fig.savefig(path, dpi=120)


def main(argv: list[str] | None = None):
    args = _common.parser(__doc__.splitlines()[0]).parse_args(argv)
    out = _common.out_dir(args)
    sizes = [10, 50, 200] if args.quick else [10, 20, 50, 100, 200, 500, 1000]
    reps = 8 if args.quick else 200
    base = load_model(_common.model_path("bus_grid.toml"))
    mu1 = base.distributions["b1"]

    def model(mu2) -> Model:
        return Model.from_game(base.game, base.spec, distributions={"mu1": mu1, "mu2": mu2},
                               name="bus_coverage")

    optimum = synthesize(model(geometric(P_TRUE))).lower
    rng = np.random.default_rng(2024)
    runs, rows = [], []
    print(f"bus 2 ~ geometric({P_TRUE}) (unknown), watched 1..{WATCH} steps a morning; "
          f"{reps} repetitions per N; true optimum {optimum:.7f}")
    print(f"{'N':>5} {'band ok':>8} {'value>=LB':>9} {'LB mean':>8} {'true val':>8} "
          f"{'gap':>7} {'width':>7} {'ours s (cpu)':>14} {'Storm |diff|':>12} "
          f"{'Storm s (cpu)':>14}")
    for n in sizes:
        lbs, vals, ok_band, ok_value, widths, secs = [], [], [], [], [], []
        storm_row: tuple[float, float, float] = (float("nan"),) * 3
        for rep in range(reps):
            cens = np.ones(n, dtype=bool)
            while cens.all():  # no bus seen: no fit (one line, exit 2 on the CLI); again
                k = rng.geometric(P_TRUE, n)
                c = rng.integers(1, WATCH + 1, n)
                cens = k > c
            fit = fit_law(np.where(cens, c, k), cens, family="geometric",
                          confidence=CONFIDENCE)
            t = _clock()
            res = synthesize(model(fit.band))
            wall, cpu = _since(t)
            assert isinstance(res, RobustResult) and res.certified, res.failed_checks
            true_value = value_under(res, P_TRUE)
            lo, hi = fit.band.hazard_band(1)
            runs.append([n, rep, fit.parameters[0].estimate, lo, hi, res.lower, res.upper,
                         true_value, lo <= P_TRUE <= hi, true_value >= res.lower - 1e-9,
                         wall, cpu])
            lbs.append(res.lower)
            vals.append(true_value)
            ok_band.append(lo <= P_TRUE <= hi)
            ok_value.append(true_value >= res.lower - 1e-9)
            widths.append(hi - lo)
            secs.append((wall, cpu))
            if rep == 0:
                drn = write_interval_drn(res.imdp, res.imdp.target, out / "robust_bus.drn",
                                         overwrite=True)
                storm_row = storm_value(drn)
                drn.unlink()
                storm_row = (storm_row[0] - res.lower, storm_row[1], storm_row[2])
        wall_mean = float(np.mean([s[0] for s in secs]))
        cpu_mean = float(np.mean([s[1] for s in secs]))
        row = [n, reps, float(np.mean(ok_band)), float(np.mean(ok_value)),
               float(np.mean(lbs)), float(np.mean(vals)), float(np.quantile(lbs, 0.1)),
               float(np.quantile(lbs, 0.9)), optimum, float(np.mean(widths)), wall_mean,
               cpu_mean, abs(storm_row[0]), storm_row[1], storm_row[2],
               storm_row[1] / wall_mean]
        rows.append(row)
        print(f"{n:5d} {row[2]:8.3f} {row[3]:9.3f} {row[4]:8.5f} {row[5]:8.5f} "
              f"{optimum - row[4]:7.4f} {row[9]:7.4f} {wall_mean:7.3f} ({cpu_mean:5.3f}) "
              f"{row[12]:12.1e} {row[13]:7.3f} ({row[14]:5.3f})")
    _common.write_csv(out / "robust_coverage.csv",
                      ["n", "repetitions", "band_coverage", "value_at_least_bound",
                       "robust_lower_mean", "true_value_mean", "robust_lower_p10",
                       "robust_lower_p90", "true_optimum", "band_width_mean", "wall_s_mean",
                       "cpu_s_mean", "storm_abs_diff_first", "storm_wall_s_first",
                       "storm_cpu_s_first", "storm_over_ours_wall"], rows)
    _common.write_csv(out / "robust_coverage_runs.csv",
                      ["n", "rep", "p_hat", "p_lo", "p_hi", "robust_lower", "robust_upper",
                       "true_value", "band_holds", "value_at_least_bound", "wall_s",
                       "cpu_s"], runs)
    plot(rows, optimum, out / "robust_coverage.png")
    print(f"wrote {out / 'robust_coverage.csv'}, robust_coverage_runs.csv, "
          "robust_coverage.png")
    return rows


if __name__ == "__main__":
    sys.exit(0 if main() else 1)

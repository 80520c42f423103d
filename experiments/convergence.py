"""Convergence of the certified bracket [lower, upper] as the truncation budget shrinks.

The model (default ``models/patrol.toml``) has events that are not memoryless: a pmf
event, a Poisson event (infinite support: the only one truncated) and a uniform one.  For
each epsilon (log-spaced, 0.3 .. 1e-4) the truncation points are chosen from epsilon,
the product is built over reachable states and both the lower model (truncation loses)
and the upper model (truncation wins) are solved.  Asserted: every solve is certified,
upper - lower <= epsilon_achieved (+1e-7), and the bracket tightens monotonically (lower
never falls, upper never rises, as epsilon shrinks).

Run: ``python experiments/convergence.py [--quick] [--out DIR] [--model FILE]``.
Writes ``convergence.png`` and ``convergence.csv``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import _common as C
import matplotlib.pyplot as plt

import mitld_lp

FULL = (0.3, 0.1, 0.03, 0.01, 3e-3, 1e-3, 3e-4, 1e-4)
QUICK = (0.3, 0.03, 3e-3)
GAP_TOL = 1e-7  # upper - lower <= epsilon_achieved + GAP_TOL
MONO_TOL = 1e-6  # the solver's certification tolerance


@dataclass(frozen=True)
class Point:
    epsilon: float
    truncation: dict[str, int]
    epsilon_achieved: float
    states: int
    transitions: int
    lower: float
    upper: float
    certified: bool
    seconds: float

    @property
    def gap(self) -> float:
        return self.upper - self.lower


def sweep(model: mitld_lp.Model, epsilons: tuple[float, ...]) -> list[Point]:
    points = []
    for eps in epsilons:
        t0 = time.perf_counter()
        r = mitld_lp.synthesize(model, epsilon=eps)
        points.append(Point(eps, dict(r.sta.truncation_points), r.sta.epsilon_achieved,
                            r.mdp.n_states, r.mdp.n_transitions, r.lower, r.upper,
                            r.certified, time.perf_counter() - t0))
    return points


def check(points: list[Point]) -> None:
    for p in points:
        assert p.certified, f"epsilon {p.epsilon}: not certified"
        assert p.lower <= p.upper + GAP_TOL, (p.epsilon, p.lower, p.upper)
        assert p.gap <= p.epsilon_achieved + GAP_TOL, (p.epsilon, p.gap, p.epsilon_achieved)
        assert p.epsilon_achieved <= p.epsilon + 1e-12, (p.epsilon, p.epsilon_achieved)
    for a, b in zip(points, points[1:], strict=False):
        assert b.lower >= a.lower - MONO_TOL, ("lower fell", a.epsilon, b.epsilon)
        assert b.upper <= a.upper + MONO_TOL, ("upper rose", a.epsilon, b.epsilon)
        assert b.gap <= a.gap + MONO_TOL, ("bracket widened", a.epsilon, b.epsilon)


def plot(points: list[Point], title: str, path) -> None:
    eps = [p.epsilon for p in points]
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True)

    ax.fill_between(eps, [p.lower for p in points], [p.upper for p in points],
                    color="tab:blue", alpha=0.12, label="certified bracket")
    ax.plot(eps, [p.upper for p in points], "v-", color="tab:red",
            label="upper (truncation counted as winning)")
    ax.plot(eps, [p.lower for p in points], "^-", color="tab:blue",
            label="lower (value of the returned policy)")
    ax.set_xscale("log")
    ax.invert_xaxis()
    ax.set_xlabel("truncation budget epsilon (log scale; tighter to the right)")
    ax.set_ylabel("probability of satisfying the task")
    ax.grid(True, which="both", alpha=0.3)
    right = ax.twinx()
    right.plot(eps, [p.states for p in points], "s--", color="0.45", markersize=5,
               label="reachable product states")
    right.set_ylabel("reachable product states", color="0.35")
    right.tick_params(axis="y", colors="0.35")
    right.set_ylim(0, max(p.states for p in points) * 1.15)
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = right.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, loc="lower right", fontsize=9)
    ax.set_title("Bracket on the optimum vs truncation budget")

    ax2.loglog(eps, eps, ":", color="0.5", label="budget epsilon")
    ax2.loglog(eps, [max(p.gap, 1e-12) for p in points], "D-", color="tab:purple",
               markersize=5, label="upper - lower")
    ax2.loglog(eps, [p.epsilon_achieved for p in points], "o", color="tab:orange",
               markersize=12, markerfacecolor="none", markeredgewidth=2,
               label="epsilon_achieved (tail mass cut off)")
    ax2.invert_xaxis()
    ax2.set_xlabel("truncation budget epsilon (log scale)")
    ax2.set_ylabel("probability (log scale)")
    ax2.grid(True, which="both", alpha=0.3)
    ax2.legend(loc="lower left", fontsize=9)
    ax2.set_title("Bracket width <= epsilon_achieved <= epsilon")
    fig.suptitle(title)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> list[Point]:
    ap = C.parser(__doc__.splitlines()[0])
    ap.add_argument("--model", default="patrol.toml",
                    help="model file (a path, or a name under models/)")
    args = ap.parse_args(argv)
    out = C.out_dir(args)
    start = time.perf_counter()
    model = mitld_lp.load_model(C.model_path(args.model))
    laws = ", ".join(f"{a} ~ {d}" for a, d in sorted(model.distributions.items()))
    points = sweep(model, QUICK if args.quick else FULL)
    check(points)

    header = ("epsilon", "truncation points", "eps_achieved", "states", "lower", "upper",
              "upper-lower", "seconds")
    rows = [[f"{p.epsilon:g}",
             ", ".join(f"{a}={T}" for a, T in sorted(p.truncation.items())) or "-",
             f"{p.epsilon_achieved:.3e}", f"{p.states:,}", f"{p.lower:.6f}",
             f"{p.upper:.6f}", f"{p.gap:.3e}", f"{p.seconds:.1f}"] for p in points]
    print(f"Convergence of the bracket on {model.name} ({laws})"
          f"{' (quick)' if args.quick else ''}\n")
    print(C.text_table(header, rows))
    print("\nChecks passed: all certified; upper - lower <= eps_achieved + 1e-7; lower "
          "non-decreasing, upper and upper - lower non-increasing as epsilon shrinks.")

    png = out / "convergence.png"
    plot(points, f"Truncation convergence on '{model.name}' ({laws})", png)
    csv_path = C.write_csv(
        out / "convergence.csv",
        ("epsilon", "truncation_points", "epsilon_achieved", "states", "transitions",
         "lower", "upper", "gap", "certified", "seconds"),
        [[repr(p.epsilon), " ".join(f"{a}={T}" for a, T in sorted(p.truncation.items())),
          repr(p.epsilon_achieved), p.states, p.transitions, repr(p.lower), repr(p.upper),
          repr(p.gap), p.certified, f"{p.seconds:.3f}"] for p in points])
    print(f"\nwrote {C.shown(png)}, {C.shown(csv_path)} "
          f"({time.perf_counter() - start:.1f} s)")
    return points


if __name__ == "__main__":
    main()

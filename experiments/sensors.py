"""The bus case with a camera that misses buses: success probability against the
camera's per-step detection probability, the fully observed answer as the limit.

``models/bus_grid.toml`` with ``[sensors] b1 = { detect = d }, b2 = { detect = d }`` for
``d`` in 0 ... 1: the robot learns of each bus only when the camera reports it (each
step after the arrival with probability ``d``, until it does), while the deadline runs
from the arrival.  For each ``d``: the certified bracket on the optimum over
observation-based policies (``d = 1`` is the fully observed problem, solved on the plain
route), its width against the epsilon achieved, the information-state product's size,
the seconds of each stage, and the value of the camera (the optimum minus the blind
robot's, ``d = 0``).  Storm (stormpy), where installed, model-checks the same
information-state MDP exported as DRN (``Pmax=? [F "accept"]``, truncation losing): its
value beside ours and the ratio of the solve times, in the same run (Storm's seconds
include parsing the DRN; ours exclude building the information states, ``build_s``).

Run: ``python experiments/sensors.py [--quick] [--out DIR]``.  ``--quick``: the camera
on bus 1 only, ``d`` in {0.5, 1}.  Writes ``sensors.csv``, ``sensors.md`` and
``sensors.png``.
"""

from __future__ import annotations

import dataclasses
from types import MappingProxyType
from typing import Any

import _common as C
import matplotlib.pyplot as plt

from mitld_lp import load_model, synthesize
from mitld_lp.sensing import Sensor

FULL = (0.0, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 1.0)
QUICK = (0.5, 1.0)
EPSILON = 1e-3


def storm(result: Any) -> tuple[float | None, float | None]:
    """Storm's ``Pmax=? [F "accept"]`` on the lower model's DRN and its seconds (None
    without stormpy)."""
    return C.storm_pmax(result.mdp, result.mdp.target)


def main(argv: list[str] | None = None) -> int:
    args = C.parser(__doc__.splitlines()[0]).parse_args(argv)
    out = C.out_dir(args)
    base = load_model(C.model_path("bus_grid.toml"))
    events = ("b1",) if args.quick else ("b1", "b2")
    header = ["detect", "route", "lower", "upper", "width", "eps_achieved", "states",
              "build_s", "solve_s", "storm_value", "storm_s", "solve/storm",
              "camera_value"]
    rows: list[list[Any]] = []
    blind = None
    for d in (QUICK if args.quick else FULL):
        model = dataclasses.replace(base, epsilon=EPSILON, sensors=MappingProxyType(
            {e: Sensor(d) for e in events}))
        r = synthesize(model)
        value, seconds = storm(r)
        if d == 0.0:
            blind = r.lower
        solve_s = r.timings["solve"]
        rows.append([
            d, r.route, f"{r.lower:.6f}", f"{r.upper:.6f}", f"{r.upper - r.lower:.2e}",
            f"{r.sta.epsilon_achieved:.2e}", r.mdp.n_states,
            f"{r.timings.get('product', 0.0):.2f}", f"{solve_s:.3f}",
            "" if value is None else f"{value:.6f}",
            "" if seconds is None else f"{seconds:.3f}",
            "" if not seconds else f"{solve_s / seconds:.2f}",
            "" if blind is None else f"{r.lower - blind:+.6f}",
        ])
        print(C.text_table(header, rows[-1:]), flush=True)
    print()
    print(f"bus_grid, camera on {', '.join(events)}, epsilon {EPSILON:g}; detect 1 is the "
          "fully observed problem (plain route), its answer the limit")
    print(C.text_table(header, rows))
    C.write_csv(out / "sensors.csv", header, rows)
    C.write_text(out / "sensors.md", C.markdown_table(header, rows))
    fig, ax = plt.subplots(figsize=(5, 3.4))
    ds = [r[0] for r in rows]
    ax.fill_between(ds, [float(r[2]) for r in rows], [float(r[3]) for r in rows],
                    alpha=0.4, label="certified bracket")
    ax.plot(ds, [float(r[2]) for r in rows], "o-", label="policy's value (lower)")
    ax.axhline(float(rows[-1][3]), color="k", ls="--", lw=0.8,
               label="fully observed (detect = 1)")
    ax.set_xlabel("camera detection probability per step")
    ax.set_ylabel("P(catch a bus)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "sensors.png", dpi=120)
    print(f"wrote {out / 'sensors.csv'}, {out / 'sensors.md'}, {out / 'sensors.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

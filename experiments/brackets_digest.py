"""A digest of the answers, to compare two checkouts digit for digit (a refactoring must
not change any answer).

Prints, one line each: every bundled model's ``solve --json`` (minus the timings), the
same problems asked for their minimum, one with ``--exact``, every cell of the
composition matrix (task class x point law / band / fit x no extra / a constraint /
``then``), the robust route on point laws, the constrained LP with no constraint, and a
problem with a sensor that misses its event.  Run it on two checkouts and diff the
outputs::

    PYTHONPATH=A python experiments/brackets_digest.py --quick > a.txt
    PYTHONPATH=B python experiments/brackets_digest.py --quick > b.txt
    diff a.txt b.txt

``--quick`` leaves out the slower models' minima; the digest is also written to
``--out`` (default ``experiments/out``, with ``--quick`` the scratch folder).  Nothing is
timed: this is not a speed claim, so there is no peer beside it.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
_TIMED = ("seconds", "timings", "solve_cpu", "time")


def _untimed(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _untimed(v) for k, v in value.items()
                if not any(t in k for t in _TIMED)}
    if isinstance(value, list):
        return [_untimed(v) for v in value]
    return value


def _cli(*args: str) -> str:
    run = subprocess.run([sys.executable, "-m", "mitld_lp", *args, "--json", "-q"],
                         capture_output=True, text=True, cwd=MODELS)
    try:
        return json.dumps(_untimed(json.loads(run.stdout)), sort_keys=True)
    except json.JSONDecodeError:
        return f"exit {run.returncode}: {run.stdout.strip()} {run.stderr.strip()[-300:]}"


def _bracket(r: Any) -> str:
    cons = [(c.name if hasattr(c, "name") else str(c), repr(getattr(c, "value", None)))
            for c in r.constraints]
    return (f"{r.route} {r.status} [{r.lower!r}, {r.upper!r}] certified={r.certified} "
            f"states={r.mdp.n_states} cons={cons} secondary={r.secondary!r}")


def _composition() -> list[str]:
    import numpy as np

    from mitld_lp import Model, fit_law, synthesize, synthesize_constrained
    from mitld_lp.distributions.literal import from_table
    from mitld_lp.problem import ProblemError
    from mitld_lp.routes.robust import synthesize_robust
    from mitld_lp.worlds.grid import GridWorld

    tasks = {"co-safe": ("D[mu] b & F(b & F[0,3] goal)", True),
             "safety": ("G (b -> F[0,3] goal)", False),
             "obligation": ("G !puddle & D[mu] b & F(b & F[0,3] goal)", True)}
    fit = fit_law(np.random.default_rng(0).geometric(0.3, 40))
    laws = {"point": from_table({"geometric": 0.3}, "mu"),
            "band": from_table({"geometric": [0.2, 0.4]}, "mu"), "fitted": fit.band}
    extras: dict[str, dict[str, Any]] = {
        "none": {}, "constraints": {"constraints": ["P(F puddle) <= 0.3"]},
        "then": {"then": "min-steps"}, "min": {"objective": "min"}}
    regions = {"goal": [(3, 2)], "puddle": [(2, 1), (2, 0)], "dock": [(1, 1)]}

    def model(task: str, law: Any, **more: Any) -> Any:
        spec, asks = tasks[task]
        world = GridWorld.make(4, 3, start=(0, 0), slip=0.2, regions=regions)
        if asks:
            return Model.from_game(world, spec, distributions={"mu": law}, **more)
        return Model.from_game(world, spec, events={"b": law}, **more)

    lines = []
    for task in tasks:
        for law, the_law in laws.items():
            for extra, kwargs in extras.items():
                try:
                    said = _bracket(synthesize(model(task, the_law), **kwargs))
                except ProblemError as exc:
                    said = f"refused: {exc}"
                lines.append(f"composition {task} {law} {extra}: {said}")
        point = model(task, laws["point"])
        lines.append(f"robust-on-point {task}: {_bracket(synthesize_robust(point))}")
        lines.append(f"constrained-lp {task}: {_bracket(synthesize_constrained(point))}")
        try:
            lines.append(f"constrained-lp band {task}: "
                         f"{_bracket(synthesize_constrained(model(task, laws['band'])))}")
        except ProblemError as exc:
            lines.append(f"constrained-lp band {task}: refused: {exc}")
    world = GridWorld.make(4, 3, start=(0, 0), slip=0.2, regions=regions)
    sensed = Model.from_game(world, "D[mu] b & F(b & F[0,3] goal)",
                             distributions={"mu": laws["point"]},
                             sensors={"b": {"detect": 0.7}})
    lines.append(f"sensed: {_bracket(synthesize(sensed))}")
    return lines


def main(argv: list[str] | None = None) -> int:
    import _common as C

    from mitld_lp import load_model, synthesize

    args = C.parser(__doc__.splitlines()[0]).parse_args(argv)
    lines = []
    for path in sorted(MODELS.glob("*.toml")):
        lines.append(f"solve {path.name}: {_cli('solve', path.name)}")
        if not args.quick or path.name in ("red_light.toml", "corridor.toml"):
            least = synthesize(load_model(path), objective="min")
            lines.append(f"objective min {path.name}: {_bracket(least)}")
    lines.append(f"solve --exact red_light.toml: "
                 f"{_cli('solve', 'red_light.toml', '--exact')}")
    lines += _composition()
    print("\n".join(lines))
    C.write_text(C.out_dir(args) / "brackets_digest.txt", "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Expected rewards on QVBS's consensus, ours beside Storm in the same run: the float
route's certified bracket of ``steps_min`` / ``steps_max`` (``R{"steps"}min=? [F
"finished"]``, ``max``) and its seconds (build and solve), Storm's sound value iteration
on its own build of the same file (1e-6 relative) and its seconds.

    python experiments/rewards_float.py --qvbs BENCHMARKS/mdp/consensus           # N=6, K=2
    python experiments/rewards_float.py --qvbs BENCHMARKS/mdp/consensus --quick   # N=2, 4

``--qvbs``: the consensus folder of a checkout of the Quantitative Verification Benchmark
Set (its ``consensus.N.prism`` files).  Writes ``rewards_float.md`` into the output
folder.  One run on a shared machine: the seconds are wall-clock, with other work
running beside it.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common  # noqa: E402

PROPS = {"steps_min": 'R{"steps"}min=? [ F "finished" ]',
         "steps_max": 'R{"steps"}max=? [ F "finished" ]'}


def storm(path: Path, prop: str, k: int) -> tuple[float, float, float]:
    """Storm's sound value iteration: its value, build and check seconds."""
    import stormpy
    import stormpy.environments

    program = stormpy.parse_prism_program(str(path))
    props = stormpy.parse_properties(prop, program)
    program, props = stormpy.instantiate_constants(program, {"K": k}, props)
    t = time.perf_counter()
    model = stormpy.build_model(program, props)
    built = time.perf_counter() - t
    env = stormpy.Environment()
    env.solver().force_soundness = True
    env.solver().min_max().method = stormpy.environments.MinMaxMethod.SOUND_VALUE_ITERATION
    t = time.perf_counter()
    result = stormpy.model_checking(model, props[0], environment=env)
    return float(result.get_value(model.initial_states[0])), built, time.perf_counter() - t


def ours(path: Path, prop: str, k: int) -> dict[str, Any]:
    """The float route: bracket, build and solve seconds, sizes."""
    import stormpy

    from mitld_lp.solvers.reward import solve_reward_float
    from mitld_lp.worlds.prism_rewards import pose_reward, reward_mdp

    program = stormpy.parse_prism_program(str(path))
    [parsed] = stormpy.parse_properties(prop, program)
    query = pose_reward("1", parsed, [r.name for r in program.reward_models])
    t = time.perf_counter()
    model = reward_mdp(path, program, query, constants={"K": k}, exact=False,
                       max_states=10**8)
    built = time.perf_counter() - t
    t = time.perf_counter()
    answer = solve_reward_float(model, query.objective)
    return {"lower": answer.lower, "upper": answer.upper, "certified": answer.certified,
            "build": built, "solve": time.perf_counter() - t, "states": model.n_states,
            "rounds": answer.rounds}


def main(argv: list[str] | None = None) -> None:
    ap = _common.parser(__doc__.split("\n")[0])
    ap.add_argument("--qvbs", type=Path, required=True,
                    help="the consensus folder of a QVBS checkout")
    args = ap.parse_args(argv)
    out = _common.out_dir(args)
    sizes = [(2, 2), (4, 2)] if args.quick else [(6, 2)]
    lines = ["| instance | property | states | ours: bracket | ours: build + solve s "
             "| Storm sound VI | Storm: build + check s |", "|---|---|---|---|---|---|---|"]
    for n, k in sizes:
        path = args.qvbs / f"consensus.{n}.prism"
        for name, prop in PROPS.items():
            a = ours(path, prop, k)
            value, s_build, s_check = storm(path, prop, k)
            row = (f"| consensus.{n}-{k} | {name} | {a['states']:,} | "
                   f"[{a['lower']!r}, {a['upper']!r}]{'' if a['certified'] else ' NOT certified'}"
                   f" | {a['build']:.1f} + {a['solve']:.1f} | {value!r} | "
                   f"{s_build:.1f} + {s_check:.1f} |")
            print(row, flush=True)
            lines.append(row)
    _common.write_text(out / "rewards_float.md", "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()

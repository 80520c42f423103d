"""Benchmark: the sensed band routes' slow cells (a camera that misses its event, a band,
with and without a constraint) before and after, in one run.

The cases are cells of ``tests/test_composition_sensed.py``'s table, built here the same
way: a 3x2 grid (slip 0.2, the goal at (2, 1), a puddle at (1, 0)), a camera on event
``b`` with ``detect = 0.6``, the law ``geometric([0.3, 0.5])`` (a band), ``epsilon =
0.05``; the task classes co-safe, safety and obligation, with a constraint
``P(F puddle) <= 0.2``, ``then = "min-steps"`` or nothing.  Each case is solved by
``synthesize`` in a child process of its own.  Per case:

* ``solve_cpu``: the CPU seconds of ``synthesize`` (the route's builds at the band's
  laws, their LPs, each candidate's interval chain and its worst case); ``unfold_cpu``:
  the answer's interval chain made once more, alone
  (:func:`mitld_lp.running.sensed_band_chain.sensed_band_unfolding_of`, the part that
  the route makes for each candidate); ``process_cpu`` the child's CPU up to the answer;
* the answer printed beside the times: ``lower``, ``upper``, ``certified``, the
  constraint's worst case; the chain's states and choices, and ``digest``: the start of
  a SHA-256 of the chain (every probability's bits, columns, rows, state's choices and
  choice names, labels, valuations, origins and reward models);
* Storm (stormpy), where installed: ``Pmin=? [F "accept"]`` with the uncertainty
  minimised on the exported chain (``storm_worst``, the controller's worst case over
  the band: ``lower``, for a minimum ``1 - upper``) and its seconds (parse and check).

``--compare DIR`` runs each case a second time, in the same run, with the ``mitld_lp`` of
that checkout (``base_*`` columns); ``same`` says ``yes`` where the bracket, the
constraint's value and the chain's digest are the same to the bit, else ``no`` (and the
script exits 1).

Run: ``python experiments/bench_sensed_corners.py [--quick] [--out DIR] [--compare DIR]
[--repeats N] [--only TEXT]``.  ``--quick``: one small cell (a scratch folder).  Writes
``bench_sensed_corners.csv``, ``.md`` and ``_machine.txt``.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import _common as C
from bench_sensed import parsed, run_child

_TASKS = {  # class -> (spec, whether the spec asks for the event's law by D[mu] b)
    "co-safe": ("D[mu] b & F(b & F[0,2] goal)", True),
    "safety": ("G (b -> F[0,2] goal)", False),
    "obligation": ("G !puddle & D[mu] b & F(b & F[0,2] goal)", True),
}
_EXTRAS: dict[str, dict[str, Any]] = {
    "none": {}, "min": {}, "constraint": {"constraints": ["P(F puddle) <= 0.2"]},
    "then": {"then": "min-steps"}}

FULL = (("obligation", "constraint"), ("co-safe", "constraint"), ("safety", "constraint"),
        ("obligation", "then"), ("co-safe", "none"), ("safety", "min"))
QUICK = (("co-safe", "none"),)

HEADER = ["case", "lower", "upper", "certified", "constraint", "chain_states", "choices",
          "digest", "storm_worst", "storm_s", "solve_cpu", "unfold_cpu", "process_cpu",
          "base_solve_cpu", "base_unfold_cpu", "base_process_cpu", "speedup", "same"]


def model_of(task: str, extra: str) -> Any:
    """The cell's model (tests/test_composition_sensed.py's ``_model`` with the band and a
    camera of ``detect = 0.6``)."""
    import dataclasses
    from types import MappingProxyType

    from mitld_lp import GridWorld, Model
    from mitld_lp.distributions.literal import from_table
    from mitld_lp.sensing import Sensor

    spec, asks = _TASKS[task]
    world = GridWorld.make(3, 2, start=(0, 0), slip=0.2,
                           regions={"goal": [(2, 1)], "puddle": [(1, 0)]})
    law = from_table({"geometric": [0.3, 0.5]}, "mu")
    laws = {"distributions": {"mu": law}} if asks else {"events": {"b": law}}
    model = Model.from_game(world, spec, objective="min" if extra == "min" else "max",
                            epsilon=0.05, **laws)
    return dataclasses.replace(model, sensors=MappingProxyType({"b": Sensor(0.6)}))


def digest(chain: Any, rewards: Any) -> str:
    """The start of a SHA-256 of the interval chain and its reward models."""
    import hashlib

    import numpy as np

    h = hashlib.sha256()
    m = chain.matrix
    for x in (m.data, m.indices, m.indptr, chain.upper, chain.row_groups, chain.origin):
        h.update(np.ascontiguousarray(x).tobytes())
    h.update(repr((chain.choice_names, [sorted(x) for x in chain.labels], chain.valuations))
             .encode())
    for name, values in rewards:
        h.update(name.encode())
        h.update(np.ascontiguousarray(values).tobytes())
    return h.hexdigest()[:16]


def worker(index: int, quick: bool, out: Path, storm: bool) -> None:
    """One case in this process: the answer and its CPU, the chain once more, Storm."""
    from mitld_lp import synthesize
    from mitld_lp.running.sensed_band_chain import (
        sensed_band_claim,
        sensed_band_unfolding_of,
        write_sensed_band_chain,
    )

    task, extra = (QUICK if quick else FULL)[index]
    model = model_of(task, extra)
    t0 = time.process_time()
    r = synthesize(model, **_EXTRAS[extra])
    solve = time.process_time() - t0
    process = time.process_time()
    t0 = time.process_time()
    chain, rewards = sensed_band_unfolding_of(r)
    unfold = time.process_time() - t0
    row: dict[str, Any] = {
        "lower": r.lower, "upper": r.upper, "certified": bool(r.certified),
        "constraint": ";".join(repr(v.certified) for v in r.constraints),
        "chain_states": chain.n_states, "choices": int(chain.matrix.shape[0]),
        "digest": digest(chain, rewards), "solve_cpu": solve, "unfold_cpu": unfold,
        "process_cpu": process, "claim": sensed_band_claim(r)[0]}
    if storm:
        from bus_camera_band import storm_worst

        with tempfile.TemporaryDirectory() as tmp:
            path = write_sensed_band_chain(r, Path(tmp) / "chain.drn")
            row["storm_worst"], row["storm_s"] = storm_worst(path)
    out.write_text(json.dumps(row), encoding="utf-8")


def least(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The first run's answer with the least CPU seconds of all runs."""
    out = dict(runs[0])
    for key in ("solve_cpu", "unfold_cpu", "process_cpu"):
        out[key] = min(r[key] for r in runs)
    return out


def fmt(key: str, v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool | str):
        return str(v)
    if isinstance(v, int):
        return f"{v:,}"
    if key in ("lower", "upper", "storm_worst"):
        return f"{v:.12f}"
    if key == "speedup":
        return f"{v:.2f}x"
    return f"{v:.3f}"


def main(argv: list[str] | None = None) -> int:
    args = parsed(__doc__.splitlines()[0], "safety", worker, argv)
    if args is None:
        return 0
    out = C.out_dir(args)
    rows = []
    for i, (task, extra) in enumerate(QUICK if args.quick else FULL):
        name = f"{task} band {extra}"
        if args.only is not None and args.only not in name:
            continue
        ours = least([run_child(__file__, i, args.quick, None, storm=k == 0)
                      for k in range(args.repeats)])
        row: dict[str, Any] = {"case": name, **ours}
        if args.compare is not None:
            base = least([run_child(__file__, i, args.quick, args.compare.resolve(),
                                    storm=False)
                          for _ in range(args.repeats)])
            for key in ("solve_cpu", "unfold_cpu", "process_cpu"):
                row[f"base_{key}"] = base[key]
            row["speedup"] = base["solve_cpu"] / ours["solve_cpu"]
            same = all(base[k] == ours[k] for k in ("lower", "upper", "certified",
                                                    "constraint", "digest", "claim"))
            row["same"] = "yes" if same else "no"
        rows.append(row)
        print(C.text_table(HEADER, [[fmt(k, row.get(k)) for k in HEADER]]), flush=True)
    table = [[fmt(k, r.get(k)) for k in HEADER] for r in rows]
    print()
    print(C.text_table(HEADER, table))
    C.write_csv(out / "bench_sensed_corners.csv", HEADER, table)
    C.write_text(out / "bench_sensed_corners.md", C.markdown_table(HEADER, table) + (
        "\nCPU seconds in a child process per case; `solve_cpu` is `synthesize`, "
        "`unfold_cpu` the answer's interval chain made once more alone, `base_*` the same "
        f"case with the package of `--compare` ({args.compare}); `same`: `yes` the same "
        "bracket, certificate, constraint value and chain (`digest`, a SHA-256 of every "
        "probability's bits, the choices, labels, valuations and rewards) to the bit; "
        "`storm_worst`: Storm's Pmin with the uncertainty minimised on the exported "
        "interval chain (parse and check, `storm_s`), the answer's lower (a minimum's "
        "1 - upper).\n"))
    from bench_scaling import machine_text

    C.write_text(out / "bench_sensed_corners_machine.txt", machine_text(
        "the machine is shared: the before/after ratio is taken in one run",
        ["each case a child process; CPU seconds (process_time inside the child)"]))
    return 0 if all(r.get("same", "yes") == "yes" for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())

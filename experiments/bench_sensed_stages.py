"""Benchmark: where the sensed route's time and peak are, stage by stage, one run.

Each case is :mod:`bench_sensed`'s (the bus case with cameras that miss buses), posed
as :func:`mitld_lp.synthesize` poses it and run in a child process of its own, cold as
the benchmarks run it: the build (``posed.route.build``: the information-state product,
:func:`mitld_lp.sensing.belief.belief_product`), then the route's solve stage
(:func:`mitld_lp.routes.sensed_solve.solve_sensed`), each of its stages timed where the
route calls it:

* ``accept``: :func:`~mitld_lp.routes.sensed_solve.sensed_acceptance` (the target on the
  information states);
* ``analysis``: :func:`mitld_lp.solvers.analysis.analyse` (both truncation models'
  quotient, end components, qualitative sets);
* ``iteration``: :func:`mitld_lp.solvers.iteration.interval_iterations`;
* ``lp``: :func:`mitld_lp.solvers.lp.solve_lp`, both models (the block LPs, or the
  greedy check where it settles a block);
* ``certificate``: :func:`mitld_lp.solvers.certify.certify`, both models (the policy's
  chain, the checked bounds);
* ``rest``: the solve stage less those (the result's records);
* ``solve``: the solve stage less the controller (as ``bench_qvbs.py``'s ``solve_cpu``);
  ``controller``: :func:`mitld_lp.sensing.observe.controller_of` (the controller's
  tables), after it.

Storm (stormpy): on a reachability task, its best sound check (``storm_check``, CPU
seconds, the fastest of :data:`bench_sweeps.METHODS` at 1e-9, sound; ``storm_method``
names it, ``storm_value`` its value, our ``lower``) of ``Pmax=? [F "accept"]`` on our
product as DRN, in the first of our runs, the parse not counted; ``solve_over_storm``
each line's ``solve`` over it.

CPU seconds (``process_time`` in the child).  Memory: ``build_Bt`` the peak resident size
during the build above the size before it, a transition; ``solve_Bt`` the largest rise of
any solve stage above the resident size where it began, a transition; ``process_Bt`` the
peak over the whole synthesis above the size before the build (``bench_qvbs.py``'s
``bytes_per_transition``).  The bracket ``[lower, upper]`` and the product's ``digest``
(:func:`bench_sensed.digest`) are printed beside each time.

``--compare DIR`` runs each case a second time in the same run with the ``mitld_lp`` of
that checkout (the ``base`` line), and says whether the products and brackets are the
same to the bit (``same``: ``yes``), or our bracket within the base's and within 1e-9
of it (``inside``: a product of fewer transitions, summed otherwise).

Run: ``python experiments/bench_sensed_stages.py [--quick] [--out DIR] [--compare DIR]
[--repeats N] [--only TEXT]``; ``--quick``: :data:`bench_sensed.QUICK`'s cases.  Writes
``bench_sensed_stages.csv`` and ``bench_sensed_stages.md``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import _common as C
import bench_sensed as B

STAGES = ("accept", "analysis", "iteration", "lp", "certificate")
HEADER = ["case", "code", "states", "transitions", "lower", "upper", "certified", "digest",
          "build",
          *STAGES, "rest", "solve", "controller", "build_Bt", "solve_Bt", "process_Bt",
          "storm_method", "storm_value", "storm_check", "solve_over_storm", "same"]


def _status_kb(key: str) -> int:
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith(key):
                return int(line.split()[1])
    return 0


class Peaks:
    """The resident size's peaks, a stage at a time (Linux: ``VmHWM`` reset through
    ``/proc/self/clear_refs``), and the largest of them all."""

    def __init__(self) -> None:
        self.top = 0

    def reset(self) -> int:
        """The peak so far kept, the peak reset; the resident size now (KiB)."""
        self.top = max(self.top, _status_kb("VmHWM"))
        with open("/proc/self/clear_refs", "w", encoding="ascii") as f:
            f.write("5")
        return _status_kb("VmRSS")

    def since(self, start: int) -> int:
        """The rise of the peak since the reset that returned ``start`` (KiB)."""
        return max(_status_kb("VmHWM") - start, 0)


def worker(index: int, quick: bool, out: Path, storm: bool) -> None:
    """One case in this process: the build, then the solve stage, each stage timed."""
    import importlib

    import mitld_lp.synthesis as synthesis
    from mitld_lp.routes import sensed_solve

    # Storm's Pmax is our lower on bus_grid's cases only (bus_puddle: a safety part;
    # bus_fit: a band, its product the middle law's)
    storm = storm and (B.QUICK if quick else B.FULL)[index][0] == "bus_grid.toml"
    peaks = Peaks()
    cpu: dict[str, float] = dict.fromkeys((*STAGES, "controller"), 0.0)
    rise = [0]

    def timed(module: Any, name: str, label: str) -> None:
        inner = getattr(module, name)

        def run(*args: Any, **kwargs: Any) -> Any:
            start = peaks.reset()
            c = time.process_time()
            got = inner(*args, **kwargs)
            cpu[label] += time.process_time() - c
            rise[0] = max(rise[0], peaks.since(start))
            return got

        setattr(module, name, run)

    # where solve_sensed and solve_models find them (imported at their call)
    for path, name, label in (("mitld_lp.solvers.analysis", "analyse", "analysis"),
                              ("mitld_lp.solvers.iteration", "interval_iterations",
                               "iteration"),
                              ("mitld_lp.solvers.lp", "solve_lp", "lp"),
                              ("mitld_lp.solvers.certify", "certify", "certificate")):
        timed(importlib.import_module(path), name, label)
    timed(sensed_solve, "sensed_acceptance", "accept")
    timed(sensed_solve, "controller_of", "controller")
    model = B.case_model(index, quick)
    posed = synthesis.pose(model)
    assert posed.route.name == "sensed", posed.route.name
    before = peaks.reset()
    c = time.process_time()
    built = posed.route.build(posed)
    build = time.process_time() - c
    build_peak = peaks.since(before)
    c = time.process_time()
    r = sensed_solve.solve_sensed(posed, built)
    solve = time.process_time() - c - cpu["controller"]
    peaks.reset()
    n = max(r.mdp.n_transitions, 1)
    row = {"states": r.mdp.n_states, "transitions": r.mdp.n_transitions,
           "lower": r.lower, "upper": r.upper, "digest": B.digest(r.mdp), "build": build,
           "certified": "yes" if r.certified else "NO",
           **cpu, "rest": solve - sum(cpu[k] for k in STAGES), "solve": solve,
           "build_Bt": build_peak * 1024 / n, "solve_Bt": rise[0] * 1024 / n,
           "process_Bt": max(peaks.top - before, 0) * 1024 / n}
    if storm:
        row["storm_method"], row["storm_check"], row["storm_value"] = storm_check(r.mdp)
    out.write_text(json.dumps(row), encoding="utf-8")


def storm_check(mdp: Any) -> tuple[str, float, float]:
    """Storm's best sound check of ``Pmax=? [F "accept"]`` on ``mdp`` as DRN (every
    method of :data:`bench_sweeps.METHODS` at its precision, sound, the parse not
    counted): the method, its CPU seconds and its value."""
    import tempfile

    import stormpy
    from bench_sweeps import METHODS, storm_env

    from mitld_lp.solvers.export import write_drn

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "m.drn"
        write_drn(mdp, mdp.target, path)
        model = stormpy.build_model_from_drn(str(path))
    prop = stormpy.parse_properties('Pmax=? [F "accept"]')[0]
    found = []
    for name in METHODS:
        env = storm_env(name)
        c = time.process_time()
        result = stormpy.model_checking(model, prop, environment=env)
        found.append((time.process_time() - c, name,
                      float(result.get_value(model.initial_states[0]))))
    cpu, name, value = min(found)
    return name.lower(), cpu, value


def least(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The first run's answer with each time the least of all runs (a shared machine)."""
    out = dict(runs[0])
    for key in ("build", *STAGES, "rest", "solve", "controller"):
        out[key] = min(r[key] for r in runs)
    return out


def same(ours: dict[str, Any], base: dict[str, Any]) -> str:
    """``yes``: the same product (digest) and bracket to the bit; ``inside``: our
    bracket within the base's and within 1e-9 of it (a product of fewer transitions,
    summed otherwise); ``no``: else."""
    if all(ours[k] == base[k] for k in ("digest", "lower", "upper")):
        return "yes"
    near = all(abs(ours[k] - base[k]) <= 1e-9 for k in ("lower", "upper"))
    inside = base["lower"] <= ours["lower"] <= ours["upper"] <= base["upper"]
    return "inside" if near and inside else "no"


def fmt(key: str, v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, str):
        return v
    if isinstance(v, int):
        return f"{v:,}"
    if key in ("lower", "upper", "storm_value"):
        return repr(v)
    return f"{v:.0f}" if key.endswith("_Bt") else f"{v:.3f}"


def main(argv: list[str] | None = None) -> int:
    args = B.parsed(__doc__.splitlines()[0], "b2@0.5", worker, argv)
    if args is None:
        return 0
    out = C.out_dir(args)
    rows = []
    for i, case in enumerate(B.QUICK if args.quick else B.FULL):
        if args.only is not None and args.only not in B.name_of(case):
            continue
        codes = [("ours", None)] + ([("base", args.compare.resolve())]
                                    if args.compare is not None else [])
        runs = {label: least([B.run_child(__file__, i, args.quick, code,
                                          label == "ours" and k == 0)
                              for k in range(args.repeats)]) for label, code in codes}
        for label, found in runs.items():
            row = {"case": B.name_of(case), "code": label, **found}
            if "storm_check" in runs["ours"]:  # both lines against Storm's one check
                row["solve_over_storm"] = found["solve"] / runs["ours"]["storm_check"]
            if label == "ours" and "base" in runs:
                row["same"] = same(found, runs["base"])
            rows.append(row)
            print(C.text_table(HEADER, [[fmt(k, row.get(k)) for k in HEADER]]), flush=True)
    table = [[fmt(k, r.get(k)) for k in HEADER] for r in rows]
    print()
    print(C.text_table(HEADER, table))
    C.write_csv(out / "bench_sensed_stages.csv", HEADER, table)
    C.write_text(out / "bench_sensed_stages.md", C.markdown_table(HEADER, table) + (
        "\nCPU seconds in a child process per case; `solve` is the route's solve stage less "
        "the controller (`controller`), `rest` the solve less the stages named; `*_Bt` "
        "peak resident bytes a transition (module docs); `base` the package of "
        f"`--compare` ({args.compare}); `same`: `yes` the same product (digest) and "
        "bracket to the bit, `inside` our bracket within the base's and 1e-9 of it.\n"))
    return 0 if all(r.get("same", "yes") != "no" and r["certified"] == "yes"
                    for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())

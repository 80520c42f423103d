"""What each of Storm's build options costs on QVBS instances, beside Storm's own build.

The PRISM load (:func:`mitld_lp.worlds.prism.load_prism`) asks Storm for a build with
some of its options (``stormpy.BuilderOptions``) and copies it through Storm's UMB
export.  Per instance (posed as ``bench_qvbs.py`` poses it), in one process, the CPU
seconds of Storm's build of the program

* ``storm``: as Storm's own run builds it for the property (``build_model(program,
  properties)``: the property's labels, its terminal states), the peer of ``load_cpu``;
* ``plain``: no option; ``all_labels``: every label of the file;
* ``labels``: every label and the choice labels (the load now, where the choices are
  named when first read: :mod:`mitld_lp.worlds.prism_names`);
* ``origins``: every label and the choice origins (the load before, for a program with
  a command without an action or a module with two commands of one action);
* ``valuations``: every label and the state valuations (left out of a whole load);
* ``origins_valuations``: both (the second build, made when a name or a state is
  first read);
* ``load``: the set the load asks for on these instances (every label,
  the choice labels, Storm's exploration checks, no state expanded past the property's
  terminal states, as the load stops where the task is decided: the same states as
  ``storm``), the peer of ``storm`` option for option;
* ``load_unchecked``: the same without Storm's exploration checks, with its
  out-of-bounds state (the copy would check every range and sum, as the load's fallback
  for a sum within PRISM's tolerance does), each build of a program parsed again (Storm
  adds its out-of-bounds variable to a program once), the parse untimed: what leaving
  the checks to the copy would gain;
* ``load_late``: ``load`` without the choice labels, as the load asks for where every
  choice is named when first read (:mod:`mitld_lp.worlds.prism_names`: a program with
  a command without an action or a module with two commands of one action);

each with the states, choices and transitions it built (the answer: every build of
one instance must agree; the peer's differ where its property stops the exploration),
the minimum and the median over ``--repeat`` builds (``load`` and ``load_unchecked`` taking
turns, so that the machine's noise hits both; ``--kinds`` measures some option sets
alone); then the export (``export``: Storm's UMB archive
of the ``labels`` build, uncompressed) and the read (``read``: the arrays copied from
it, :func:`mitld_lp.worlds.prism_tables.read_export`).

    python experiments/bench_build_options.py --qvbs /work/shared/qvbs \\
        --only consensus.4-4.c2 firewire_dl.3-600.deadline --out /tmp/options
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import sys
import tempfile
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import _common  # noqa: E402
import bench_qvbs  # noqa: E402  (the same instances, posed the same way)

OPTIONS = ("plain", "all_labels", "labels", "origins", "valuations", "origins_valuations",
           "load", "load_unchecked", "load_late")


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _options(stormpy: Any, kind: str, prop: Any = None) -> Any:
    if kind.startswith("load"):  # stopped where the property is decided
        o = stormpy.BuilderOptions([prop.get_raw_formula()])
        o.set_exploration_checks(kind != "load_unchecked")
        o.set_add_out_of_bounds_state(kind == "load_unchecked")
        o.set_build_all_labels()
        if kind != "load_late":
            o.set_build_choice_labels()
        return o
    o = stormpy.BuilderOptions()
    if kind != "plain":
        o.set_build_all_labels()
    if kind == "labels":
        o.set_build_choice_labels()
    if kind in ("origins", "origins_valuations"):
        o.set_build_choice_origins()
    if kind in ("valuations", "origins_valuations"):
        o.set_build_state_valuations()
    return o


def _program(stormpy: Any, job: dict[str, Any]) -> tuple[Any, set[str]]:
    """The instance's program, its constants given, and its undefined constants."""
    program = stormpy.parse_prism_program(job["prism"])
    undefined = {k.name for k in program.constants if not k.defined}
    given = {k: v for k, v in job["constants"].items() if k in undefined}
    return (stormpy.instantiate_constants(program, given)[0] if given else program), undefined


def measure(job: dict[str, Any], repeat: int, kinds: tuple[str, ...] = OPTIONS,
            ) -> dict[str, Any]:
    """The figures of one instance (the module docstring)."""
    import stormpy
    import stormpy.io

    from mitld_lp.worlds.prism_tables import read_export

    program, undefined = _program(stormpy, job)
    text = job["property"]
    for name, value in job["constants"].items():  # the properties file's own constants
        if name not in undefined:
            shown = str(value).lower() if isinstance(value, bool) else str(value)
            text = re.sub(rf"(?<![\w\"]){re.escape(name)}(?![\w\"])", shown, text)
    props = stormpy.parse_properties(text, program)[:1]
    row: dict[str, Any] = {}

    def timed(name: str, build: Any) -> Any:
        best, model = None, None
        for _ in range(repeat):
            del model
            c = _cpu()
            model = build()
            t = _cpu() - c
            best = t if best is None else min(best, t)
        row[f"{name}_cpu"] = round(best, 4)
        row[f"{name}_size"] = (f"{model.nr_states}/{model.nr_choices}/"
                               f"{model.nr_transitions}")
        return model

    timed("storm", lambda: stormpy.build_model(program, props))
    kept = None
    for kind in [k for k in OPTIONS if k in kinds and not k.startswith("load")]:
        model = timed(kind, lambda kind=kind: stormpy.build_model(
            program, options=_options(stormpy, kind, props[0])))
        if kind == "labels":
            kept = model
        del model
    loads = [k for k in ("load", "load_unchecked", "load_late") if k in kinds]
    times: dict[str, list[float]] = {k: [] for k in loads}
    for r in range(repeat):  # taking turns
        for kind in loads if r % 2 == 0 else loads[::-1]:
            fresh = program if kind != "load_unchecked" else _program(stormpy, job)[0]
            fresh_props = stormpy.parse_properties(text, fresh)[:1]
            options = _options(stormpy, kind, fresh_props[0])
            c = _cpu()
            model = stormpy.build_model(fresh, options=options)
            times[kind].append(_cpu() - c)
            row[f"{kind}_size"] = f"{model.nr_states}/{model.nr_choices}/{model.nr_transitions}"
            del model
    for kind, t in times.items():
        row[f"{kind}_cpu"] = round(min(t), 4)
        row[f"{kind}_median"] = round(sorted(t)[len(t) // 2], 4)
    if kept is None:
        kept = stormpy.build_model(program, options=_options(stormpy, "labels"))
    options = stormpy.io.UmbExportOptions()
    options.compression = stormpy.io.CompressionMode.NO_COMPRESSION
    with tempfile.TemporaryDirectory() as folder:
        c = _cpu()
        stormpy.io.export_to_umb(kept, os.path.join(folder, "m.umb"), options=options)
        row["export_cpu"] = round(_cpu() - c, 4)
    c = _cpu()
    read_export(kept, job["prism"])
    row["read_cpu"] = round(_cpu() - c, 4)  # its own export again, and the arrays
    return row


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--qvbs", type=Path, required=True)
    ap.add_argument("--only", nargs="+", required=True)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--kinds", nargs="+", choices=OPTIONS, default=list(OPTIONS),
                    help="the option sets measured (default all; 'plain' is always built, "
                    "for the ratios)")
    ap.add_argument("--out", type=Path, default=None,
                    help="the folder written (required unless --quick)")
    ap.add_argument("--quick", action="store_true",
                    help=f"one repeat, written to the scratch folder {_common.QUICK_OUT}")
    args = ap.parse_args(argv)
    if args.quick:
        args.repeat, args.out = 1, _common.QUICK_OUT
    elif args.out is None:
        ap.error("--out is required (or --quick)")
    with tempfile.TemporaryDirectory() as work:
        found, _ = bench_qvbs.jobs(args.qvbs, 0, bench_qvbs.MAX_STATES, bench_qvbs.FAMILIES,
                                   Path(work))
        jobs = {inst.name: job for inst, job in found}
        missing = sorted(set(args.only) - set(jobs))
        if missing:
            raise SystemExit(f"not found: {', '.join(missing)}")
        rows = []
        for name in args.only:
            kinds = tuple(k for k in OPTIONS if k in args.kinds or k == "plain")
            row = {"instance": name, **measure(jobs[name], args.repeat, kinds)}
            base = row["plain_cpu"]
            print("  ".join(f"{k}={v}" for k, v in row.items())
                  + "  " + "  ".join(f"{k}/plain={row[f'{k}_cpu'] / base:.2f}"
                                     for k in kinds[1:]), flush=True)
            rows.append(row)
    args.out.mkdir(parents=True, exist_ok=True)
    kinds = tuple(k for k in OPTIONS if k in args.kinds or k == "plain")
    medians = [f"{k}_median" for k in ("load", "load_unchecked", "load_late") if k in kinds]
    head = ["instance", *[f"{k}_{x}" for k in ("storm", *kinds) for x in ("cpu", "size")],
            *medians, "export_cpu", "read_cpu"]
    lines = [",".join(head)] + [",".join(str(r[h]) for h in head) for r in rows]
    (args.out / "bench_build_options.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    shown = ("storm", *kinds, *[m.removesuffix("_cpu") for m in medians], "export", "read")
    md = ["| instance | " + " | ".join(shown) + " |", "|---" * (len(shown) + 1) + "|"]
    for r in rows:
        md.append(f"| {r['instance']} ({r['plain_size']}) | " + " | ".join(
            f"{r[k if k.endswith('_median') else f'{k}_cpu']:.3f}" for k in shown) + " |")
    (args.out / "bench_build_options.md").write_text(
        "CPU seconds of Storm's build per option set, the least of the repeats "
        "(states/choices/transitions of the plain build beside the name; `storm`: Storm's "
        "own build for the property; `*_median`: the median of the repeats)\n\n"
        + "\n".join(md) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()

"""The command line's verbs over many runs: batches of model files (``solve a.toml
b.toml``), sweeps (``sweep``), pictures (``plot``) and Monte-Carlo rollouts
(``simulate``).  Imported by :mod:`mitld_lp.cli` when one of them runs; shares its
output helpers."""

from __future__ import annotations

import argparse
import glob
import json
import logging
import re
from pathlib import Path
from typing import Any

from mitld_lp import defaults
from mitld_lp.cli.arguments import bounded_int, probability_budget
from mitld_lp.cli.kernel import (
    EXIT_INTERNAL,
    EXIT_OK,
    EXIT_UNCERTIFIED,
    EXIT_USAGE,
    UsageError,
    add_model_argument,
    args_json,
    count_text,
    error_record,
    file_time_limit,
    is_pattern,
    json_text,
    model_options,
    other_file,
    output_path,
    read_model,
    say,
    say_answer,
    solve_settings,
    time_left,
    unconstrained,
    write_file,
)
from mitld_lp.report import bracket_text
from mitld_lp.util import progress
from mitld_lp.util.text import printable


def _batch_exit(records: list[dict[str, Any]], noun: str) -> int:
    """The exit status of many runs: 1 if one hit a bug, else 2 if a model was wrong,
    else 3 if one has no certified answer, else 0; said in one line on stderr (the runs'
    own lines name each failure)."""
    statuses = [r["status"] for r in records]
    failed = sum(1 for r in records if not r.get("certified"))
    of = f"{failed} of {count_text(len(records), noun)}"
    if "error" in statuses:
        say(f"internal error: {statuses.count('error')} of {count_text(len(records), noun)} "
            "failed unexpectedly (see their lines; please report this)")
        return EXIT_INTERNAL
    if "model_error" in statuses:
        say(f"error: {statuses.count('model_error')} of {count_text(len(records), noun)} "
            "could not be read or posed (see their lines)")
        return EXIT_USAGE
    if failed:
        say(f"stopped: {of} without a certified answer (see their lines)")
        return EXIT_UNCERTIFIED
    return EXIT_OK


def solve_batch(args: argparse.Namespace) -> int:
    """``solve a.toml b.toml 'models/*.toml'``: each model file in turn, one line each
    (a JSON object with ``--json``); a model that fails is its line, not the end."""
    from mitld_lp.sweep.rows import MODEL_ERROR, run_model

    if args.policy:
        raise UsageError("--policy writes the policy of one model; give one model file")
    records: list[dict[str, Any]] = []
    seen: set[str] = set()
    todo: list[tuple[str, bool]] = []  # (a file, True) or (a pattern matching none, False)
    for name in args.model:
        matches = sorted(glob.glob(name, recursive=True)) if is_pattern(name) else [name]
        if not matches:
            todo.append((name, False))
        for path in matches:
            if path not in seen:  # a file named twice is solved once
                seen.add(path)
                todo.append((path, True))
    bar = progress.bar(None, total=len(todo), desc="batch", unit="model", leave=False)
    try:
        for path, found in todo:
            if not found:
                records.append({"file": path, **error_record(
                    MODEL_ERROR, "no file matches this pattern"), "certified": False})
            else:
                # a model file's own time limit binds its run, the load included; one
                # that cannot stop by itself (a world's factory looping) stops the batch,
                # as the flag would (the watchdog of mitld_lp.cli.main)
                own = None if args.time_limit is not None else file_time_limit(
                    path, args.max_memory)
                command, args.limit = args.limit, own or args.limit
                try:
                    outcome = run_model(
                        lambda path=path: read_model(args, path),
                        solve_settings(args), constraints=tuple(args.constraint),
                        then=args.then, whole=True)
                finally:
                    args.limit = command
                records.append({"file": path, **outcome.summary} if outcome.summary else {
                    "file": path, **error_record(outcome.status, outcome.error.removeprefix(
                        f"{path}: ") if outcome.error else ""), "certified": False})
            _batch_line(records[-1], args.json)
            bar.update()
    finally:
        bar.close()
    return _batch_exit(records, "model")


def _batch_line(record: dict[str, Any], as_json: bool) -> None:
    if as_json:
        say_answer(json_text(record))
    elif "error" in record:
        say_answer(f"{printable(record['file'])}: {record['status']}: {record['error']}")
    else:
        exact = record.get("exact_bracket")  # --exact: the fraction (or both models')
        shown = "" if not exact else f" exact {exact[0]}" if exact[0] == exact[1] else (
            f" exact in [{exact[0]}, {exact[1]}]")
        if record.get("bands_reading") == "best":  # no guarantee: said on every line
            shown += " (the best law of the bands: Pmaxmax)"
        say_answer(f"{printable(record['file'])}: {bracket_text(record['lower'], record['upper'])} "
                   f"certified {'yes' if record['certified'] else 'NO'} ({record['status']}, "
                   f"{record['states']} states, {record['seconds']:.3f} s){shown}")


def args_sweep(p: argparse.ArgumentParser) -> None:
    p.add_argument("sweep", help="a sweep file (models/sweeps/*.toml; see docs/sweeps.md)")
    p.add_argument("-o", "--out", metavar="RESULTS",
                   help="the results file, .csv or .parquet (default: NAME.csv here, NAME "
                        "the sweep's name); points already in it are not solved again")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=bounded_int(1, 1024), default=1, metavar="N",
                       help="solve N points at a time, in local processes")
    where.add_argument("--dask", metavar="ADDRESS",
                       help="solve the points on the Dask scheduler at ADDRESS "
                            "(tcp://host:8786)")
    p.add_argument("--retries", type=bounded_int(0, 100), default=2, metavar="N",
                   help="Dask: run a failed task up to N more times (default 2)")
    p.add_argument("--retry-failed", action="store_true",
                   help="solve again the points whose row has a failure status")
    p.add_argument("--force", action="store_true",
                   help="start RESULTS anew, even when it holds another sweep's rows")
    args_json(p)


def cmd_sweep(args: argparse.Namespace) -> int:
    """Solve every point of a sweep not yet in its results file; print a summary."""
    from collections import Counter

    from mitld_lp.sweep import SweepError, load_sweep, run_sweep

    try:
        sw = load_sweep(args.sweep)
    except SweepError as err:
        what = other_file(args.sweep, None, "sweep")
        if what:
            raise SweepError(f"{err}; {what}") from None
        raise
    out = Path(args.out or re.sub(r"[^\w.-]", "_", sw.name) + ".csv")
    if not args.verbose:  # the bar says how far it is; each point's stages would drown it
        logging.getLogger("mitld_lp").setLevel(logging.WARNING)
    run = run_sweep(sw, out, workers=args.workers, dask=args.dask, retries=args.retries,
                    force=args.force, retry_failed=args.retry_failed,
                    progress=None)  # a bar on a terminal, none under -q or --json
    statuses = Counter(r["status"] for r in run.rows)
    shown: dict[tuple[str, str], dict[str, Any]] = {}
    for r in run.failed:  # the first five failures of different kinds
        if r["error"] and (r["status"], r["error"]) not in shown and len(shown) < 5:
            shown[r["status"], r["error"]] = {c: r[c] for c in sw.columns}
    if args.json:
        say_answer(json_text({"sweep": sw.name, "points": len(run.rows), "solved": run.computed,
                     "reused": run.reused, "statuses": dict(statuses.most_common()),
                     "certified": len(run.rows) - len(run.failed),
                     "failures": [{"status": s, "error": e, "at": at}
                                  for (s, e), at in shown.items()],
                     "files": {"results": str(out)}}))
        return _batch_exit(list(run.rows), "point")
    say_answer(f"sweep:      {sw.name} ({count_text(len(run.rows), 'point')}: {run.computed} "
               f"solved now, {run.reused} already in {out})")
    say_answer("status:     " + ", ".join(f"{n} {s}" for s, n in statuses.most_common()))
    say_answer(f"certified:  {len(run.rows) - len(run.failed)} of {len(run.rows)}")
    for (status, error), at in shown.items():
        where = ", ".join(f"{c} = {json.dumps(v)}" for c, v in at.items())
        say_answer(f"  {status} at {where or 'the base model'}: {error}")
    say_answer(f"results:    {out}")
    return _batch_exit(list(run.rows), "point")


def _size(text: str) -> tuple[int, int]:
    """A picture size in pixels, ``WIDTHxHEIGHT``."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m or not all(100 <= int(v) <= 20_000 for v in m.groups()):
        raise argparse.ArgumentTypeError(
            f"must be WIDTHxHEIGHT in pixels, each in 100..20000, got {text!r}")
    return int(m.group(1)), int(m.group(2))


def args_plot(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", help="a model file of a grid world (draws its policy) or a "
                                 "sweep's results file, .csv or .parquet (draws a column)")
    p.add_argument("-o", "--out", required=True, metavar="FILE",
                   help="the picture: .png, .svg or .pdf")
    p.add_argument("--situation", action="append", metavar="S",
                   help='model: a panel for this situation, e.g. "occurred=b1" or '
                        '"pending=b2; automaton=3; clock=0" (repeat for more panels; '
                        "default: the initial one)")
    p.add_argument("--x", help="results: the parameter on the x axis (its last key will do)")
    p.add_argument("--y", help="results: the column on the y axis (lower, upper, states...)")
    p.add_argument("--by", action="append", metavar="PARAMETER",
                   help="results: one line per value of PARAMETER (repeatable; default: "
                        "every other parameter that varies)")
    p.add_argument("--size", type=_size, default=(800, 600), metavar="WxH",
                   help="the picture's size in pixels (default 800x600)")
    args_json(p)
    p.add_argument("--epsilon", type=probability_budget,
                   help="model: truncation budget in (0, 1) (default: the model's)")
    p.add_argument("--max-states", type=bounded_int(1), metavar="N",
                   help="model: refuse products larger than N states (exit 3; default: the "
                        "model file's [budgets], else 5,000,000)")
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")


def cmd_plot(args: argparse.Namespace) -> int:
    """Draw a grid world's policy, or a column of a sweep's results."""
    from mitld_lp import plot

    out = output_path(args.out, args.force, "--out", plot.FIGURE_SUFFIXES)
    table = Path(args.input).suffix.lower() in (".csv", ".parquet")
    if table and (args.x is None or args.y is None):
        raise UsageError(f"plot {args.input}: a results file needs --x and --y")
    wrong = ("--situation" if args.situation else "--epsilon" if args.epsilon is not None
             else "--max-states" if args.max_states is not None else None) if table else (
        "--x" if args.x else "--y" if args.y else "--by" if args.by else None)
    if wrong:
        raise UsageError(f"plot {args.input}: {wrong} applies to "
                         f"{'a model file' if table else 'a results file'}")
    try:
        if table:
            fig = plot.sweep_figure(args.input, args.x, args.y, by=args.by, size=args.size)
        else:
            from mitld_lp.problem import settings_from
            from mitld_lp.synthesis import pose, solve

            situations = [plot.parse_situation(s) for s in args.situation or [""]]
            model = read_model(args, args.input, max_states=args.max_states)
            posed = unconstrained(pose(model, settings=settings_from(
                epsilon=args.epsilon, max_states=args.max_states,
                time_limit=time_left(args))), "plot")
            if posed.route.observation_based:  # mitld_lp.sensing: refused before work
                raise UsageError("plot: the model has sensors that miss events; the policy "
                                 "map of an observation-based controller is not drawn yet")
            result = solve(posed)
            fig = plot.policy_figure(result, situations, size=args.size)
    except plot.PlotError as err:
        raise UsageError(str(err)) from None
    write_file(out, lambda p: plot.save(fig, p, overwrite=True))  # checked above, before work
    say_answer(json_text({"files": {"out": str(out)}, "size": list(args.size)}) if args.json else
               f"wrote {out} ({args.size[0]}x{args.size[1]} pixels)")
    return EXIT_OK


def args_simulate(p: argparse.ArgumentParser) -> None:
    add_model_argument(p)
    p.add_argument("-n", "--runs", type=bounded_int(1, defaults.MAX_RUNS),
                   default=defaults.RUNS, help=f"number of rollouts (1..{defaults.MAX_RUNS:,})")
    p.add_argument("--seed", type=bounded_int(0), default=0, help="a non-negative seed")
    p.add_argument("--max-steps", type=bounded_int(1, defaults.MAX_STEPS_LIMIT),
                   default=defaults.MAX_STEPS,
                   help="steps each run is watched (a run keeping a safety part unviolated "
                        "that long counts as a success; undecided ones as failures)")
    args_json(p)
    from mitld_lp.cli.constrained import args_constraints

    args_constraints(p)


def cmd_simulate(args: argparse.Namespace) -> int:
    """Monte-Carlo rollouts of the synthesised controller in the untruncated world."""
    from mitld_lp.problem import settings_from
    from mitld_lp.running.simulate import simulate
    from mitld_lp.synthesis import pose, solve

    model = read_model(args)
    r = solve(pose(model, args.constraint, then=args.then,
                   settings=settings_from(**model_options(args))))
    if r.controller is None:
        raise UsageError(f"simulate: no controller to run: the synthesis is {r.status}")
    if r.part.observation_based:  # the hidden events and sensors drawn (mitld_lp.sensing)
        from mitld_lp.sensing.observe import simulate_sensed

        sim = simulate_sensed(model, r.controller, runs=args.runs, seed=args.seed,
                              max_steps=args.max_steps)
    else:
        sim = simulate(model, r.controller, runs=args.runs, seed=args.seed,
                       max_steps=args.max_steps)
    robust = r.summary().get("robust", False)
    # the bands read for their best law: the nominal law does at most as well as the best
    # (for a minimum, at least as badly)
    best = robust and r.part.reading == "best"
    below = sim.ci_high >= r.lower if r.objective == "min" else sim.ci_low <= r.upper
    out = {
        "runs": sim.runs,
        "successes": sim.successes,
        "estimate": sim.estimate,
        "ci95": [sim.ci_low, sim.ci_high],
        "certified_bracket": [r.lower, r.upper],
        # a robust bracket bounds the worst law of the bands; runs follow the nominal laws
        "consistent": below if best else
                      (sim.ci_low <= r.upper or robust) and sim.ci_high >= r.lower,
        "beyond_model": sim.beyond_model,
        "undecided": sim.undecided,
        "horizon": sim.horizon,
        "kept": sim.kept,
        "seed": sim.seed,
    }
    if args.json:
        say_answer(json_text(out))
    else:
        say_answer(f"success rate: {sim.estimate:.4f}  95% CI [{sim.ci_low:.4f}, {sim.ci_high:.4f}]"
              f"  ({sim.successes}/{sim.runs}, seed {sim.seed}, horizon {sim.horizon} steps)")
        if sim.kept:
            say_answer(f"kept:         {count_text(sim.kept, 'run')} kept the safety part to the "
                       "horizon (counted as successes)")
        say_answer(f"certified:    {bracket_text(r.lower, r.upper)}  "
              + ("consistent" if out["consistent"] else "INCONSISTENT"))
        if sim.beyond_model:
            say_answer(f"note:         {count_text(sim.beyond_model, 'run')} had an event after "
                       "its truncation point")
        if robust:
            say_answer("note:         runs follow each band's nominal law; the bracket is the "
                       + ("worst" if r.part.reading == "worst" else "best (Pmaxmax)")
                       + " case over the bands")
    return EXIT_OK

"""The command line of constrained synthesis: ``solve --constraint/--then`` and
``pareto``.  Wired into :mod:`mitld_lp.cli` (which owns exit codes and error lines)."""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path
from typing import Any

from mitld_lp.logic.constraints import THEN, ConstraintError
from mitld_lp.report import bracket_text

__all__ = ["args_constraints", "solve", "args_pareto", "cmd_pareto"]


def args_constraints(p: argparse.ArgumentParser) -> None:
    p.add_argument("--constraint", action="append", default=[], metavar="C",
                   help="'P(FORMULA) <= x', 'P(FORMULA) >= x', 'E(steps) <= x' or "
                        "'E(cost) <= x' (repeatable; see docs/constraints.md)")
    p.add_argument("--then", choices=THEN,
                   help="then minimise expected steps / cost among the optimal policies")


def _usage(exc: ConstraintError) -> Exception:
    from mitld_lp.cli.kernel import UsageError

    return UsageError(str(exc))


def solve(args: argparse.Namespace, posed: Any, policy_file: Path | None) -> int:
    """Run the constrained synthesis of a posed problem and print it; exit 0 when
    certified, 3 when infeasible, failed or not certified."""
    from mitld_lp.cli.kernel import EXIT_OK, EXIT_UNCERTIFIED, json_text, print_head, say_answer
    from mitld_lp.synthesis import solve

    model = posed.model
    try:
        r = solve(posed)
    except ConstraintError as exc:
        raise _usage(exc) from None
    summary = r.summary()
    if policy_file is not None and r.prob is not None:
        _write_policy(r.policy_table(), policy_file)
        summary["policy_file"] = str(policy_file)
    if args.json:
        say_answer(json_text(summary))
    else:
        print_head(model, r.objective)
        say_answer(f"status:       {r.status}")
        if r.bands:
            said = ("worst case over the bands " if r.part.reading == "worst"
                    else "best case over the bands (Pmaxmax) ")
            say_answer("robust:       " + said
                       + ", ".join(f"{e} ~ {law}" for e, law in r.bands.items()) + f"; {r.message}")
        if r.status == "failed" and r.message:  # no controller; a bound where one is known
            say_answer(f"optimum in:   {bracket_text(r.lower, r.upper)}  ({r.message})")
        if r.status == "optimal":
            say_answer(f"optimum in:   {bracket_text(r.lower, r.upper)}  (LP {r.value:.7f})")
            parts = {k: v for k, v in r.width.items() if k != "total" and v}
            if set(parts) - {"solver"}:
                say_answer(f"width:        {r.width['total']:.3g} = " + " + ".join(
                    f"{k} {v:.3g}" for k, v in parts.items()))
            at = {None: "", "worst law": "  (at the worst law of the bands)",
                  "chosen law": "  (at the law of the bands the answer chose, not a worst "
                                "case)"}[summary["expected_at"]]
            say_answer(f"E(steps):     {r.steps:.6g}{at}")
            if r.then:
                say_answer(f"then {r.then}: {r.secondary:.6g}{at}")
            elif not r.bands:  # the steps of one optimal policy, not the fewest
                say_answer("note:         E(steps) is that of one optimal policy; --then min-steps "
                           "gives the fewest among them")
            say_answer("certified:    " + ("yes" if r.certified else "NO"))
            for c in r.failed_checks:
                say_answer(f"  failed: {c.name}: {c.detail}")
        for c in r.constraints:
            if r.status == "failed" and c.value != c.value:  # failed with no policy
                say_answer(f"constraint:   {c.constraint}: no controller returned")
            elif r.status != "infeasible":  # a failed band answer: its policy's worst cases
                word = "<=" if c.constraint.sense == "<=" else ">="
                say_answer(f"constraint:   {c.constraint}: {c.value:.7g} ("
                           + (f"holds: certified {word} {c.certified!r}" if c.holds else
                        f"MISSES by up to {c.miss:.3g}: certified {word} {c.certified!r}")
                     + ")")
            elif c.feasible_bound is None and r.bands:  # the robust line says why
                say_answer(f"constraint:   {c.constraint}: not met under every law of the "
                           "bands")
            else:
                tight = "none (the others are infeasible)" if c.feasible_bound is None else (
                    f"{c.feasible_bound:.7g}")
                say_answer(f"constraint:   {c.constraint}: tightest feasible bound {tight}")
        say_answer(f"sizes:        {r.merged.mdp.n_states} states ({r.mdp.n_states} in the "
                   f"product), {summary['randomized_states']} randomised")
        if policy_file is not None and r.prob is not None:
            say_answer(f"policy:       {policy_file}")
    return EXIT_OK if r.status == "optimal" and r.certified else EXIT_UNCERTIFIED


def _write_policy(rows: list[dict[str, Any]], path: Path) -> None:
    from mitld_lp.cli.kernel import write_file
    from mitld_lp.files import write as files

    def write(p: Path) -> None:
        if p.suffix.lower() == ".json":
            with files.replacing(p) as fh:
                fh.write(json.dumps(rows, default=repr, indent=1))
            return
        with files.replacing(p, newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]) if rows else ["action"])
            w.writeheader()
            for row in rows:
                w.writerow({k: json.dumps(v, default=repr) if isinstance(v, list | tuple)
                            else v for k, v in row.items()})

    write_file(path, write)


def args_pareto(p: argparse.ArgumentParser) -> None:
    from mitld_lp.cli.arguments import bounded_int
    from mitld_lp.cli.kernel import add_model_argument, args_json

    add_model_argument(p)
    p.add_argument("--against", required=True, metavar="Q",
                   help="steps, cost, or 'P(FORMULA)' (a risk bounded from above)")
    p.add_argument("--points", type=bounded_int(2, 1000), default=11)
    p.add_argument("--csv", metavar="FILE", help="also write the points (.csv)")
    p.add_argument("--plot", metavar="FILE", help="the curve (.png), certified points only")
    p.add_argument("--force", action="store_true", help="overwrite existing files")
    args_json(p)


def cmd_pareto(args: argparse.Namespace) -> int:
    """Trace the certified trade-off curve: its points on stdout (with ``--json`` one
    object), in ``--csv`` and drawn in ``--plot``."""
    from mitld_lp.cli.kernel import (
        EXIT_OK,
        EXIT_UNCERTIFIED,
        json_text,
        output_path,
        say_answer,
        write_file,
    )
    from mitld_lp.tradeoff import pareto, plot, write_csv

    out_csv = args.csv and output_path(args.csv, args.force, "--csv", (".csv",))
    out_png = args.plot and output_path(args.plot, args.force, "--plot", (".png",))
    from mitld_lp.cli.kernel import model_options, read_model

    model = read_model(args)
    try:
        points = pareto(model, args.against, args.points, **model_options(args))
    except ConstraintError as exc:
        raise _usage(exc) from None
    said: dict[str, Any] = {"against": args.against, "files": {}}
    if out_csv:
        write_file(out_csv, lambda p: write_csv(points, p, overwrite=True))
        said["files"]["csv"] = str(out_csv)
    if out_png:
        left = plot(points, out_png, args.against, model.name, overwrite=True)
        said["files"]["plot"] = str(out_png)
        said["left_out"] = left
    code = EXIT_OK if all(p.certified or p.status == "infeasible" for p in points) else (
        EXIT_UNCERTIFIED)
    if args.json:
        said["points"] = [{"bound": p.bound, "lower": p.lower, "upper": p.upper,
                           "achieved": p.achieved, "status": p.status,
                           "certified": p.certified} for p in points]
        say_answer(json_text(said))
        return code
    if out_csv:
        say_answer(f"wrote {out_csv}")
    if out_png:
        say_answer(f"wrote {out_png}" + (f" ({left} uncertified points left out)" if left else ""))
    for p in points:
        say_answer(f"{p.bound:12.6g}  {bracket_text(p.lower, p.upper)}  {p.status}"
                   f"{'' if p.certified else ' (not certified)'}")
    return code

"""The command line's formula verbs: ``check`` (parse and classify) and ``dta`` (the
automaton)."""

from __future__ import annotations

import argparse
import json

from mitld_lp import defaults
from mitld_lp.cli.arguments import bounded_int
from mitld_lp.cli.kernel import (
    _DOT_SUFFIXES,
    _USER_ERRORS,
    EXIT_OK,
    _count,
    _out,
    _output_path,
    _write,
)
from mitld_lp.files import write as files
from mitld_lp.logic.fragment import FragmentReport, check
from mitld_lp.logic.parser import ParseError, parse_source

__all__ = ["args_check", "cmd_check", "args_dta", "cmd_dta"]

# --------------------------------------------------------------------------- check


def args_check(p: argparse.ArgumentParser) -> None:
    p.add_argument("formula", help='an MITLD formula, e.g. "F[0,3] A & D[mu] b"')
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _report_json(report: FragmentReport) -> dict[str, object]:
    return {
        "formula": str(report.formula),
        "nnf": str(report.nnf),
        "events": {event: str(mu) for event, mu in report.events},
        "horizon": report.horizon,
        "co_safe": report.co_safe,
        "class": report.fragment,
        "supported": True,
    }


def cmd_check(args: argparse.Namespace) -> int:
    """Parse and classify a formula: normalised form, NNF, events, horizon."""
    try:
        report = check(parse_source(args.formula))
    except _USER_ERRORS as err:
        if args.json:
            out: dict[str, object] = {"supported": False, "error": str(err)}
            if isinstance(err, ParseError):
                out.update(line=err.line, column=err.column)
            print(json.dumps(out))
        raise
    if args.json:
        print(json.dumps(_report_json(report)))
        return EXIT_OK
    events = ", ".join(f"{event} ~ {mu}" for event, mu in report.events) or "none"
    horizon = "unbounded" if report.horizon is None else str(report.horizon)
    print(f"formula:   {report.formula}")
    print(f"nnf:       {report.nnf}")
    print(f"events:    {events}")
    print(f"horizon:   {horizon}")
    print(f"class:     {report.fragment}")
    print("supported: yes")
    return EXIT_OK


# --------------------------------------------------------------------------- dta


def args_dta(p: argparse.ArgumentParser) -> None:
    p.add_argument("formula", help="an MITLD formula (D[mu] a reads as F a)")
    p.add_argument("--dot", metavar="FILE", help="write the automaton as Graphviz DOT")
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    p.add_argument("--max-states", type=bounded_int(1), default=defaults.MAX_AUTOMATON_STATES,
                   metavar="N", help="refuse automata with more states (checked while it "
                                     "is built; exit 3)")


def cmd_dta(args: argparse.Namespace) -> int:
    """Print the minimal DTA: each state's location and clocks, and its transitions."""
    from mitld_lp.automata.translate import to_dta

    path = None if args.dot is None else _output_path(args.dot, args.force, "--dot",
                                                       _DOT_SUFFIXES)
    report = check(parse_source(args.formula))
    formula = report.formula
    dta = to_dta(report, max_states=args.max_states)
    if path:
        _write(path, lambda p: files.write_text(p, dta.to_dot(), overwrite=True))
        _out(f"wrote {path} ({_count(dta.n_states, 'state')})")
        return EXIT_OK
    shown = [dta.location(i) for i in range(dta.n_states)]
    locations = {loc.obligation for loc in shown}
    clocks = {name for loc in shown for name, _ in loc.clocks}
    print(f"formula:   {formula}")
    print(f"states:    {dta.n_states} ({_count(len(locations), 'location')}, "
          f"{_count(len(clocks), 'clock')})")
    print(f"atoms:     {', '.join(dta.atoms)}")
    for i, loc in enumerate(shown):
        tag = " (initial)" if i == dta.initial else ""
        tag += " (accepting)" if dta.is_accepting(i) else ""
        tag += " (rejecting)" if dta.is_rejecting(i) else ""
        tag += " (safe)" if dta.is_safe(i) else ""
        print(f"  {i}{tag}: {loc}")
        for target, guard in sorted(dta.guards(i).items()):
            print(f"      --[{guard}]--> {target}")
    return EXIT_OK


"""The command line's formula verbs: ``check`` (parse and classify) and ``dta`` (the
automaton)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from mitld_lp import defaults
from mitld_lp.cli.arguments import bounded_int
from mitld_lp.cli.kernel import (
    DOT_SUFFIXES,
    EXIT_OK,
    args_json,
    count_text,
    json_text,
    output_path,
    say_answer,
    write_file,
)
from mitld_lp.files import write as files
from mitld_lp.logic.fragment import FragmentReport, check
from mitld_lp.logic.parser import parse_source

if TYPE_CHECKING:
    from mitld_lp.automata.dta import DTA

__all__ = ["args_check", "cmd_check", "args_dta", "cmd_dta"]

# --------------------------------------------------------------------------- check


def args_check(p: argparse.ArgumentParser) -> None:
    p.add_argument("formula", help='an MITLD formula, e.g. "F[0,3] A & D[mu] b"')
    args_json(p)


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
    """Parse and classify a formula: normalised form, NNF, events, horizon.  A formula
    that is wrong or not supported is an error (with ``--json`` the error object, with
    ``"supported": false``, :func:`mitld_lp.cli.kernel.say_error`)."""
    report = check(parse_source(args.formula))
    if args.json:
        say_answer(json_text(_report_json(report)))
        return EXIT_OK
    events = ", ".join(f"{event} ~ {mu}" for event, mu in report.events) or "none"
    horizon = "unbounded" if report.horizon is None else str(report.horizon)
    say_answer(f"formula:   {report.formula}")
    say_answer(f"nnf:       {report.nnf}")
    say_answer(f"events:    {events}")
    say_answer(f"horizon:   {horizon}")
    say_answer(f"class:     {report.fragment}")
    say_answer("supported: yes")
    return EXIT_OK


# --------------------------------------------------------------------------- dta


def args_dta(p: argparse.ArgumentParser) -> None:
    p.add_argument("formula", help="an MITLD formula (D[mu] a reads as F a)")
    p.add_argument("--dot", metavar="FILE", help="write the automaton as Graphviz DOT")
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    p.add_argument("--max-states", type=bounded_int(1), default=defaults.MAX_AUTOMATON_STATES,
                   metavar="N", help="refuse automata with more states (checked while it "
                                     "is built; exit 3)")
    args_json(p)


def cmd_dta(args: argparse.Namespace) -> int:
    """Print the minimal DTA: each state's location and clocks, and its transitions."""
    from mitld_lp.automata.translate import to_dta

    path = None if args.dot is None else output_path(args.dot, args.force, "--dot",
                                                       DOT_SUFFIXES)
    report = check(parse_source(args.formula))
    formula = report.formula
    dta = to_dta(report, max_states=args.max_states)
    if path:
        write_file(path, lambda p: files.write_text(p, dta.to_dot(), overwrite=True))
        if args.json:
            say_answer(json_text({"formula": str(formula), "states": dta.n_states,
                         "files": {"dot": str(path)}}))
        else:
            say_answer(f"wrote {path} ({count_text(dta.n_states, 'state')})")
        return EXIT_OK
    shown = [dta.location(i) for i in range(dta.n_states)]
    locations = {loc.obligation for loc in shown}
    clocks = {name for loc in shown for name, _ in loc.clocks}
    if args.json:
        say_answer(json_text(_dta_json(dta, str(formula), shown, len(locations), clocks)))
        return EXIT_OK
    say_answer(f"formula:   {formula}")
    say_answer(f"states:    {dta.n_states} ({count_text(len(locations), 'location')}, "
               f"{count_text(len(clocks), 'clock')})")
    say_answer(f"atoms:     {', '.join(dta.atoms)}")
    for i, loc in enumerate(shown):
        say_answer(f"  {i}{''.join(f' ({tag})' for tag in _tags(dta, i))}: {loc}")
        for target, guard in sorted(dta.guards(i).items()):
            say_answer(f"      --[{guard}]--> {target}")
    return EXIT_OK


def _tags(dta: DTA, i: int) -> list[str]:
    """What a state of the automaton is: initial, accepting, rejecting, safe."""
    return [tag for tag, yes in (("initial", i == dta.initial),
                                 ("accepting", dta.is_accepting(i)),
                                 ("rejecting", dta.is_rejecting(i)), ("safe", dta.is_safe(i)))
            if yes]


def _dta_json(dta: DTA, formula: str, shown: list[Any], locations: int,
              clocks: set[str]) -> dict[str, Any]:
    """``dta --json``: what the text says, one record per state."""
    return {"formula": formula, "states": dta.n_states, "locations": locations,
            "clocks": sorted(clocks), "atoms": list(dta.atoms), "initial": dta.initial,
            "automaton": [{"state": i, "location": str(loc), "tags": _tags(dta, i),
                           "transitions": [{"guard": str(guard), "to": target} for
                                           target, guard in sorted(dta.guards(i).items())]}
                          for i, loc in enumerate(shown)]}

"""The ``mitld-lp`` command.

Each verb is a pair of functions, ``_args_<verb>(parser)`` adding its arguments and
``_cmd_<verb>(args) -> int`` running it, registered once in :data:`_VERBS`.  A user error
(a ``ValueError`` subclass listed in :data:`_USER_ERRORS`) prints one line
``mitld-lp: error: <reason>`` on stderr and exits 2; anything unexpected prints a one-line
internal error and exits 1.  This module is the only place in the package that prints.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable

from mitld_lp.logic.fragment import FragmentError, FragmentReport, check
from mitld_lp.logic.parser import ParseError, parse

PROG = "mitld-lp"

#: Exceptions that mean "the input is wrong" (exit 2), not "the program is wrong".
_USER_ERRORS: tuple[type[Exception], ...] = (ParseError, FragmentError)

EXIT_OK, EXIT_INTERNAL, EXIT_USAGE = 0, 1, 2


# --------------------------------------------------------------------------- check


def _args_check(p: argparse.ArgumentParser) -> None:
    p.add_argument("formula", help='an MITLD formula, e.g. "F[0,3] A & D[mu] b"')
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _report_json(report: FragmentReport) -> dict[str, object]:
    return {
        "formula": str(report.formula),
        "nnf": str(report.nnf),
        "events": {event: str(mu) for event, mu in report.events},
        "horizon": report.horizon,
        "co_safe": report.co_safe,
        "supported": True,
    }


def _cmd_check(args: argparse.Namespace) -> int:
    """Parse and classify a formula: normalised form, NNF, events, horizon."""
    try:
        report = check(parse(args.formula))
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
    print("supported: yes")
    return EXIT_OK


# --------------------------------------------------------------------------- registry

#: (verb, one-line help, add arguments, run).  Add a verb by appending one row.
_VERBS: list[
    tuple[str, str, Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int]]
] = [
    ("check", "parse a formula and check it is in the supported fragment", _args_check, _cmd_check),
]


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Policy synthesis for MITLD specifications by occupancy-measure LP.",
    )
    sub = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
    for verb, help_text, add_args, run in _VERBS:
        p = sub.add_parser(verb, help=help_text, description=help_text)
        add_args(p)
        p.set_defaults(run=run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``); return the exit status."""
    parser = _build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as stop:  # argparse has printed usage or help already
        return stop.code if isinstance(stop.code, int) else EXIT_USAGE
    try:
        return args.run(args)
    except _USER_ERRORS as err:
        print(f"{PROG}: error: {err}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except Exception as err:  # noqa: BLE001 - the CLI never shows a traceback
        first = str(err).splitlines()[0] if str(err) else ""
        print(
            f"{PROG}: internal error: {type(err).__name__}: {first} (please report this)",
            file=sys.stderr,
        )
        return EXIT_INTERNAL


if __name__ == "__main__":
    sys.exit(main())

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
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mitld_lp import defaults
from mitld_lp.automata.translate import TranslationError
from mitld_lp.distributions import DistributionError
from mitld_lp.logic.fragment import FragmentError, FragmentReport, check
from mitld_lp.logic.parser import ParseError, parse
from mitld_lp.model import ModelError
from mitld_lp.product import ProductTooLarge

if TYPE_CHECKING:
    from mitld_lp.model import Model
    from mitld_lp.synthesis import Built

PROG = "mitld-lp"

#: Exceptions that mean "the input is wrong" (exit 2), not "the program is wrong".
_USER_ERRORS: tuple[type[Exception], ...] = (
    ParseError,
    FragmentError,
    ModelError,
    DistributionError,
    TranslationError,
    ProductTooLarge,
    FileExistsError,
)

#: 3: the solver did not return a certified answer (the result is still printed).
EXIT_OK, EXIT_INTERNAL, EXIT_USAGE, EXIT_UNCERTIFIED = 0, 1, 2, 3


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


# --------------------------------------------------------------------------- dta


def _args_dta(p: argparse.ArgumentParser) -> None:
    p.add_argument("formula", help="an MITLD formula (D[mu] a reads as F a)")
    p.add_argument("--dot", metavar="FILE", help="write the automaton as Graphviz DOT")
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")


def _cmd_dta(args: argparse.Namespace) -> int:
    """Print the minimal DTA: each state's location and clocks, and its transitions."""
    from mitld_lp.automata.dta import _guards
    from mitld_lp.automata.translate import to_dta

    formula = parse(args.formula)
    check(formula)
    dta = to_dta(formula)
    if args.dot:
        path = Path(args.dot)
        if path.exists() and not args.force:
            raise FileExistsError(f"{path}: exists; pass --force to overwrite it")
        path.write_text(dta.to_dot())
        print(f"wrote {path} ({dta.n_states} states)")
        return EXIT_OK
    locations = {_strip_clocks(dta.location(i)) for i in range(dta.n_states)}
    clocks = {name for i in range(dta.n_states) for name, _ in dta.clocks(i)}
    print(f"formula:   {formula}")
    print(f"states:    {dta.n_states} ({len(locations)} locations, {len(clocks)} clocks)")
    print(f"atoms:     {', '.join(dta.atoms)}")
    for i in range(dta.n_states):
        tag = " (initial)" if i == dta.initial else ""
        tag += " (accepting)" if dta.is_accepting(i) else ""
        tag += " (rejecting)" if dta.is_rejecting(i) else ""
        print(f"  {i}{tag}: {dta.location(i)}")
        for target, guard in sorted(_guards(dta.delta[i]).items()):
            print(f"      --[{guard}]--> {target}")
    return EXIT_OK


def _strip_clocks(location: str) -> str:
    from mitld_lp.automata.dta import _CLOCK

    return _CLOCK.sub("", location)


# --------------------------------------------------------------------------- model verbs


def _args_model(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", help="a model file (models/*.toml)")
    p.add_argument("--epsilon", type=float, help="truncation budget (default: the model's)")
    p.add_argument(
        "--no-clock-reduction",
        action="store_true",
        help="give every event an age clock, truncated as in the paper",
    )
    p.add_argument("--max-states", type=int, default=defaults.MAX_STATES, metavar="N")


def _build(args: argparse.Namespace) -> tuple[Model, Built]:
    """Model file -> (model, its automaton, STA and product MDP)."""
    from mitld_lp.model import load_model
    from mitld_lp.synthesis import build_product

    model = load_model(args.model)
    built = build_product(
        model.game, model.spec, model.distributions,
        epsilon=model.epsilon if args.epsilon is None else args.epsilon,
        clock_reduction=not args.no_clock_reduction, max_states=args.max_states,
    )
    return model, built


def _args_info(p: argparse.ArgumentParser) -> None:
    _args_model(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _cmd_info(args: argparse.Namespace) -> int:
    """The product's sizes, truncation points and the epsilon achieved."""
    from mitld_lp.product import component_counts

    model, built = _build(args)
    sta, mdp = built.sta, built.mdp
    out: dict[str, Any] = {
        "model": model.name,
        "spec": str(model.spec),
        "dta_states": sta.dta.n_states,
        **component_counts(mdp),
        "truncation_points": sta.truncation_points,
        "epsilon": model.epsilon if args.epsilon is None else args.epsilon,
        "epsilon_achieved": sta.epsilon_achieved,
    }
    if args.json:
        print(json.dumps(out))
    else:
        width = max(map(len, out))
        for k, v in out.items():
            print(f"{k + ':':<{width + 1}} {v}")
    return EXIT_OK


def _args_solve(p: argparse.ArgumentParser) -> None:
    _args_model(p)
    p.add_argument("--method", choices=("lp", "vi"), default="lp")
    p.add_argument("--solver", default="CLARABEL",
                   help="an LP solver cvxpy has installed (CLARABEL, HIGHS, SCS, ...)")
    p.add_argument("--backend", choices=("cvxpy", "direct"), default="cvxpy",
                   help="direct: call Clarabel on the sparse matrices, no cvxpy")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _cmd_solve(args: argparse.Namespace) -> int:
    """Synthesise the policy: the certified bracket, the value, the sizes."""
    from mitld_lp.model import load_model
    from mitld_lp.synthesis import synthesize

    model = load_model(args.model)
    r = synthesize(
        model,
        epsilon=args.epsilon,
        method=args.method,
        solver=args.solver,
        backend=args.backend,
        clock_reduction=not args.no_clock_reduction,
        max_states=args.max_states,
    )
    summary = r.summary()
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"model:        {model.name}  ({model.spec})")
        print(f"optimum in:   [{r.lower:.7f}, {r.upper:.7f}]"
              f"  (epsilon achieved {r.epsilon_achieved:.3g})")
        print(f"value:        {r.value:.7f}  ({r.method}, status {r.status.value})")
        print("certified:    " + ("yes" if r.certified else "NO"))
        for c in r.failed_checks:
            print(f"  failed: {c.name}: {c.detail}")
        print(f"sizes:        {r.sizes.dta_states} automaton states, {r.sizes.states} states,"
              f" {r.sizes.choices} choices, {r.sizes.transitions} transitions")
        if r.truncation_points:
            print(f"truncation:   {dict(r.truncation_points)}")
        print("seconds:      " + ", ".join(f"{k} {v:.3f}" for k, v in r.timings.items()))
    return EXIT_OK if r.certified else EXIT_UNCERTIFIED


def _args_export(p: argparse.ArgumentParser) -> None:
    _args_model(p)
    p.add_argument("--lp", metavar="FILE", help="the occupancy LP, as .mps or .lp")
    p.add_argument("--drn", metavar="FILE", help="the product MDP in Storm's DRN format")
    p.add_argument("--upper", action="store_true",
                   help="count the truncation sink as winning (the upper model)")
    p.add_argument("--force", action="store_true", help="overwrite existing files")


def _cmd_export(args: argparse.Namespace) -> int:
    """Write the LP (through HiGHS) and/or the MDP (DRN) for external tools."""
    from mitld_lp.solvers.export import write_drn, write_lp

    if not args.lp and not args.drn:
        raise ModelError("export: nothing to do; give --lp FILE and/or --drn FILE")
    for given in (args.lp, args.drn):
        if given and Path(given).exists() and not args.force:
            raise FileExistsError(f"{given}: exists; pass --force to overwrite it")
    mdp = _build(args)[1].mdp
    target = mdp.target | mdp.truncated if args.upper else mdp.target
    if args.lp:
        print(f"wrote {write_lp(mdp, target, args.lp, overwrite=args.force, everywhere=True)}")
    if args.drn:
        print(f"wrote {write_drn(mdp, target, args.drn, overwrite=args.force)}")
    return EXIT_OK


def _args_simulate(p: argparse.ArgumentParser) -> None:
    _args_model(p)
    p.add_argument("-n", "--runs", type=int, default=10_000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-steps", type=int, default=500)
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _cmd_simulate(args: argparse.Namespace) -> int:
    """Monte-Carlo rollouts of the synthesised controller in the untruncated world."""
    from mitld_lp.model import load_model
    from mitld_lp.simulate import simulate
    from mitld_lp.synthesis import synthesize

    if args.runs <= 0:
        raise ModelError(f"--runs: must be positive, got {args.runs}")
    model = load_model(args.model)
    r = synthesize(model, epsilon=args.epsilon, clock_reduction=not args.no_clock_reduction,
                   max_states=args.max_states)
    sim = simulate(model.game, r.sta, r.controller, runs=args.runs, seed=args.seed,
                   max_steps=args.max_steps)
    out = {
        "runs": sim.runs,
        "successes": sim.successes,
        "estimate": sim.estimate,
        "ci95": [sim.ci_low, sim.ci_high],
        "certified_bracket": [r.lower, r.upper],
        "consistent": sim.ci_low <= r.upper and sim.ci_high >= r.lower,
        "beyond_model": sim.beyond_model,
        "undecided": sim.undecided,
        "seed": sim.seed,
    }
    if args.json:
        print(json.dumps(out))
    else:
        print(f"success rate: {sim.estimate:.4f}  95% CI [{sim.ci_low:.4f}, {sim.ci_high:.4f}]"
              f"  ({sim.successes}/{sim.runs}, seed {sim.seed})")
        print(f"certified:    [{r.lower:.7f}, {r.upper:.7f}]  "
              + ("consistent" if out["consistent"] else "INCONSISTENT"))
        if sim.beyond_model:
            print(f"note:         {sim.beyond_model} runs had an event after its truncation point")
    return EXIT_OK


# --------------------------------------------------------------------------- registry

#: (verb, one-line help, add arguments, run).  Add a verb by appending one row.
_VERBS: list[
    tuple[str, str, Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int]]
] = [
    ("check", "parse a formula and check it is in the supported fragment", _args_check, _cmd_check),
    ("dta", "print the formula's automaton, or write it as DOT", _args_dta, _cmd_dta),
    ("info", "build the product of a model and print its sizes", _args_info, _cmd_info),
    ("solve", "synthesise the optimal policy and its certified bracket", _args_solve,
     _cmd_solve),
    ("export", "write the LP (MPS/LP) and the MDP (Storm DRN)", _args_export, _cmd_export),
    ("simulate", "Monte-Carlo rollouts of the synthesised controller", _args_simulate,
     _cmd_simulate),
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
    except BrokenPipeError:  # the reader (e.g. `| head`) went away: not an error
        sys.stderr.close()
        return EXIT_OK
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

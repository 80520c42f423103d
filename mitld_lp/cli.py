"""The ``mitld-lp`` command.

Each verb is a pair of functions, ``_args_<verb>(parser)`` adding its arguments and
``_cmd_<verb>(args) -> int`` running it, registered once in :data:`_VERBS`.  Exit codes:

* 0 -- done (a certified answer, for ``solve``);
* 2 -- the input is wrong (a bad argument, formula, model file or output path): one line
  ``mitld-lp: error: <reason>`` on stderr, checked before any work where it can be;
* 3 -- a solver or budget stop: the answer is not certified, a budget (``--max-states``,
  ``--time-limit``) was hit; the status is printed;
* 130 -- interrupted (Ctrl-C), within a fraction of a second, whatever the stage;
* 1 -- a bug: a one-line internal error.

Every message is one line of printable characters (names a user wrote are escaped).
This module is the only place in the package that prints.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from mitld_lp import defaults
from mitld_lp.automata.translate import AutomatonTooLarge, TranslationError
from mitld_lp.distributions import DistributionError
from mitld_lp.logic.fragment import FragmentError, FragmentReport, check
from mitld_lp.logic.parser import ParseError, parse_source
from mitld_lp.model import ModelError
from mitld_lp.product import ProductTooLarge
from mitld_lp.text import printable

if TYPE_CHECKING:
    from mitld_lp.model import Model
    from mitld_lp.synthesis import Built

PROG = "mitld-lp"

class UsageError(ValueError):
    """A bad command-line argument or output path (exit 2)."""


#: Exceptions that mean "the input is wrong" (exit 2), not "the program is wrong".
_USER_ERRORS: tuple[type[Exception], ...] = (
    ParseError,
    FragmentError,
    ModelError,
    DistributionError,
    TranslationError,
    UsageError,
    FileExistsError,
)

#: Exceptions that mean "a budget stopped the work" (exit 3).
_BUDGET_STOPS: tuple[type[Exception], ...] = (ProductTooLarge, AutomatonTooLarge)

#: 3: no certified answer (a solver status or a budget stop; the status is printed).
EXIT_OK, EXIT_INTERNAL, EXIT_USAGE, EXIT_UNCERTIFIED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130


# --------------------------------------------------------------------------- argument types


def _probability_budget(text: str) -> float:
    """An ``--epsilon``: a number strictly between 0 and 1."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number in (0, 1), got {text!r}") from None
    if not 0.0 < value < 1.0:  # also refuses nan and inf
        raise argparse.ArgumentTypeError(f"must be in (0, 1), got {text!r}")
    return value


def _bounded_int(low: int, high: int | None = None) -> Callable[[str], int]:
    def parse_int(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
        if value < low or (high is not None and value > high):
            bound = f">= {low:,}" if high is None else f"in {low:,}..{high:,}"
            raise argparse.ArgumentTypeError(f"must be an integer {bound}, got {text}")
        return value

    parse_int.__name__ = "integer"
    return parse_int


_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def _memory_size(text: str) -> int:
    """A byte count with an optional binary unit: ``500M``, ``4G``, ``1.5G``."""
    body = text.strip().upper().removesuffix("B").removesuffix("I")
    unit = body[-1:] if body[-1:] in _UNITS and body[-1:] else ""
    try:
        value = float(body[: len(body) - len(unit)]) * _UNITS[unit]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be a size such as 4G or 500M, got {text!r}") from None
    if not 1 <= value < float(1 << 60):
        raise argparse.ArgumentTypeError(f"must be a positive size, got {text!r}")
    return int(value)


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of seconds, got {text!r}") from None
    if not value > 0.0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number of seconds, got {text!r}")
    return value


def _solver_name(text: str) -> str:
    """An LP solver name, in any case; checked against cvxpy's installed solvers."""
    name = text.strip().upper()
    if name == "CLARABEL":  # the default needs no cvxpy import to be checked
        return name
    import cvxpy

    installed = cvxpy.installed_solvers()
    if name not in installed:
        raise argparse.ArgumentTypeError(
            f"unknown or not installed LP solver {text!r} (installed: {', '.join(installed)})"
        )
    return name


# --------------------------------------------------------------------------- output files


def _output_path(given: str, force: bool, what: str, suffixes: tuple[str, ...] = ()) -> Path:
    """Check, before any work, that ``given`` can be written: its folder exists, it is no
    folder itself, its suffix is one of ``suffixes``, and it exists only with ``--force``."""
    path = Path(given)
    if suffixes and path.suffix.lower() not in suffixes:
        raise UsageError(f"{what} {given}: the suffix must be one of {', '.join(suffixes)}")
    if path.is_dir():
        raise UsageError(f"{what} {given}: is a directory")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise UsageError(f"{what} {given}: the folder {parent} does not exist")
    if path.exists() and not force:
        raise FileExistsError(f"{given}: exists; pass --force to overwrite it")
    return path


def _write(path: Path, write: Callable[[Path], object]) -> None:
    """Run ``write(path)``; an OS error (disk full, no permission) is a one-line error."""
    try:
        write(path)
    except OSError as exc:
        raise UsageError(f"{path}: cannot write: {exc.strerror or exc}") from exc


def _dumps(record: object) -> str:
    """JSON with non-finite numbers as ``null`` (``NaN`` is not JSON)."""

    def clean(x: object) -> object:
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, list | tuple):
            return [clean(v) for v in x]
        return x

    return json.dumps(clean(record), allow_nan=False)


_command = threading.local()
"""Per command thread: ``cancelled``, an Event set when the command was interrupted or
ran out of time.  Its thread may still be finishing a native call, and must not print
an answer after the stop was reported."""


def _out(text: str = "") -> None:
    """Print one line of the command's answer on stdout (nothing once cancelled)."""
    cancelled = getattr(_command, "cancelled", None)
    if cancelled is None or not cancelled.is_set():
        print(text)


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
        "class": report.fragment,
        "supported": True,
    }


def _cmd_check(args: argparse.Namespace) -> int:
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


def _args_dta(p: argparse.ArgumentParser) -> None:
    p.add_argument("formula", help="an MITLD formula (D[mu] a reads as F a)")
    p.add_argument("--dot", metavar="FILE", help="write the automaton as Graphviz DOT")
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    p.add_argument("--max-states", type=int, default=200_000, metavar="N",
                   help="refuse automata with more states (checked while it is built)")


def _cmd_dta(args: argparse.Namespace) -> int:
    """Print the minimal DTA: each state's location and clocks, and its transitions."""
    from mitld_lp.automata.translate import to_dta

    path = args.dot and _output_path(args.dot, args.force, "--dot", (".dot", ".gv"))
    report = check(parse_source(args.formula))
    formula = report.formula
    dta = to_dta(report, max_states=args.max_states)
    if path:
        _write(path, lambda p: p.write_text(dta.to_dot()))
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


def _count(n: int, noun: str) -> str:
    """``n`` with ``noun`` in the singular or plural: "1 clock", "2 clocks"."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


# --------------------------------------------------------------------------- model verbs


def _args_model(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", help="a model file (models/*.toml)")
    p.add_argument("--epsilon", type=_probability_budget,
                   help="truncation budget in (0, 1) (default: the model's)")
    p.add_argument(
        "--no-clock-reduction",
        action="store_true",
        help="give every event an age clock, truncated as in the paper",
    )
    p.add_argument("--max-states", type=_bounded_int(1), default=defaults.MAX_STATES,
                   metavar="N", help="refuse products larger than N states (exit 3)")
    p.add_argument("--max-memory", type=_memory_size, metavar="SIZE",
                   help="refuse products needing more memory, e.g. 4G or 500M "
                        "(default: half the machine's memory; exit 3)")


def _build(args: argparse.Namespace) -> tuple[Model, Built]:
    """Model file -> (model, its automaton, STA and product MDP)."""
    from mitld_lp.model import load_model
    from mitld_lp.synthesis import build_product

    model = load_model(args.model)
    built = build_product(
        model.game, model.spec, model.distributions,
        epsilon=model.epsilon if args.epsilon is None else args.epsilon,
        clock_reduction=not args.no_clock_reduction, max_states=args.max_states,
        max_memory=args.max_memory,
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
        _out(_dumps(out))
    else:
        width = max(map(len, out))
        for k, v in out.items():
            _out(f"{k + ':':<{width + 1}} {v}")
    return EXIT_OK


def _args_solve(p: argparse.ArgumentParser) -> None:
    _args_model(p)
    p.add_argument("--method", choices=("lp", "vi"), default="lp")
    p.add_argument("--solver", type=_solver_name, default="CLARABEL",
                   help="an LP solver cvxpy has installed, any case (CLARABEL, HIGHS, ...)")
    p.add_argument("--backend", choices=("auto", "cvxpy", "direct"), default="auto",
                   help="direct: Clarabel on the sparse matrices; cvxpy: through cvxpy "
                        "(any solver); auto (default): direct for Clarabel, else cvxpy")
    p.add_argument("--no-decompose", action="store_true",
                   help="solve one monolithic LP instead of one LP per strongly connected "
                        "block in topological order")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--policy", metavar="FILE",
                   help="write the policy table (.csv or .json): one row per state")
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    _constrained().args_constraints(p)


def _constrained() -> Any:
    """The constrained-synthesis command line (its own module)."""
    from mitld_lp import cli_constrained

    return cli_constrained


def _cmd_solve(args: argparse.Namespace) -> int:
    """Synthesise the policy: the certified bracket, the value, the sizes."""
    from mitld_lp.model import load_model
    from mitld_lp.synthesis import synthesize

    if args.backend == "direct" and args.solver != "CLARABEL":
        raise UsageError(f"--backend direct runs only Clarabel, not {args.solver}; "
                         "use --backend cvxpy (or auto) for other solvers")
    policy_file = args.policy and _output_path(args.policy, args.force, "--policy",
                                               (".csv", ".json"))
    model = load_model(args.model)
    if _constrained().wanted(args, model):
        return _constrained().solve(args, model, policy_file or None)
    r = synthesize(
        model,
        epsilon=args.epsilon,
        method=args.method,
        solver=args.solver,
        backend=args.backend,
        clock_reduction=not args.no_clock_reduction,
        max_states=args.max_states,
        max_memory=args.max_memory,
        decompose=not args.no_decompose,
        time_limit=_time_left(args),
    )
    summary = r.summary()
    if policy_file:
        _write(policy_file, lambda p: r.write_policy(p, overwrite=True))
        summary["policy_file"] = str(policy_file)
    if args.json:
        _out(_dumps(summary))
    else:
        _out(f"model:        {model.name}  ({model.spec})")
        _out(f"optimum in:   [{r.lower:.7f}, {r.upper:.7f}]"
              f"  (epsilon achieved {r.epsilon_achieved:.3g})")
        _out(f"value:        {r.value:.7f}  ({r.method}, status {r.status.value})")
        _out("certified:    " + ("yes" if r.certified else "NO"))
        for c in r.failed_checks:
            _out(f"  failed: {c.name}: {c.detail}")
        _out(f"sizes:        {r.sizes.dta_states} automaton states, {r.sizes.states} states,"
              f" {r.sizes.choices} choices, {r.sizes.transitions} transitions")
        if r.truncation_points:
            _out(f"truncation:   {dict(r.truncation_points)}")
        _out("seconds:      " + ", ".join(f"{k} {v:.3f}" for k, v in r.timings.items()))
        if policy_file:
            _out(f"policy:       {policy_file}")
    return EXIT_OK if r.certified else EXIT_UNCERTIFIED


def _time_left(args: argparse.Namespace) -> float | None:
    """Seconds left of ``--time-limit`` (None without one): the solvers stop with status
    ``time_limit`` and their bracket so far; the command's own watchdog is the backstop."""
    if args.time_limit is None:
        return None
    return max(args.time_limit - (time.monotonic() - args.started), 0.0)


def _args_export(p: argparse.ArgumentParser) -> None:
    _args_model(p)
    p.add_argument("--lp", metavar="FILE",
                   help="the occupancy LP, whose optimum is the value, as .mps or .lp")
    p.add_argument("--drn", metavar="FILE", help="the product MDP in Storm's DRN format")
    p.add_argument("--upper", action="store_true",
                   help="count the truncation sink as winning (the upper model)")
    p.add_argument("--force", action="store_true", help="overwrite existing files")


def _cmd_export(args: argparse.Namespace) -> int:
    """Write the LP (through HiGHS) and/or the MDP (DRN) for external tools."""
    from mitld_lp.solvers.export import write_drn, write_lp

    if not args.lp and not args.drn:
        raise UsageError("export: nothing to do; give --lp FILE and/or --drn FILE")
    lp = args.lp and _output_path(args.lp, args.force, "--lp", (".mps", ".lp"))
    drn = args.drn and _output_path(args.drn, args.force, "--drn", (".drn",))
    if lp and drn and lp.resolve() == drn.resolve():
        raise UsageError(f"--lp and --drn name the same file {args.lp}")
    mdp = _build(args)[1].mdp
    target = mdp.target | mdp.truncated if args.upper else mdp.target
    if lp:
        _write(lp, lambda p: write_lp(mdp, target, p, overwrite=True))
        _out(f"wrote {lp}")
    if drn:
        _write(drn, lambda p: write_drn(mdp, target, p, overwrite=True))
        _out(f"wrote {drn}")
    return EXIT_OK


_MAX_RUNS = 100_000_000
"""More rollouts than this would take days; the estimate's 95% CI is then +-1e-4."""
_MAX_STEPS = 1_000_000


def _args_simulate(p: argparse.ArgumentParser) -> None:
    _args_model(p)
    p.add_argument("-n", "--runs", type=_bounded_int(1, _MAX_RUNS), default=10_000,
                   help=f"number of rollouts (1..{_MAX_RUNS:,})")
    p.add_argument("--seed", type=_bounded_int(0), default=0, help="a non-negative seed")
    p.add_argument("--max-steps", type=_bounded_int(1, _MAX_STEPS), default=500,
                   help="steps after which a run still undecided counts as undecided")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _cmd_simulate(args: argparse.Namespace) -> int:
    """Monte-Carlo rollouts of the synthesised controller in the untruncated world."""
    from mitld_lp.model import load_model
    from mitld_lp.simulate import simulate
    from mitld_lp.synthesis import synthesize

    model = load_model(args.model)
    r = synthesize(model, epsilon=args.epsilon, clock_reduction=not args.no_clock_reduction,
                   max_states=args.max_states, max_memory=args.max_memory,
                   time_limit=_time_left(args))
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
        _out(_dumps(out))
    else:
        _out(f"success rate: {sim.estimate:.4f}  95% CI [{sim.ci_low:.4f}, {sim.ci_high:.4f}]"
              f"  ({sim.successes}/{sim.runs}, seed {sim.seed})")
        _out(f"certified:    [{r.lower:.7f}, {r.upper:.7f}]  "
              + ("consistent" if out["consistent"] else "INCONSISTENT"))
        if sim.beyond_model:
            _out(f"note:         {_count(sim.beyond_model, 'run')} had an event after its "
                 "truncation point")
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
    ("pareto", "the certified curve of success probability against steps, cost or a risk",
     lambda p: _constrained().args_pareto(p), lambda a: _constrained().cmd_pareto(a)),
]


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: a bad argument raises :class:`UsageError`."""

    def error(self, message: str) -> NoReturn:  # type: ignore[override]
        raise UsageError(f"{self.prog}: {message} (see {self.prog} --help)")


def _build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog=PROG,
        description="Policy synthesis for MITLD specifications by occupancy-measure LP.",
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {_version()}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
    for verb, help_text, add_args, run in _VERBS:
        p = sub.add_parser(verb, help=help_text, description=help_text)
        add_args(p)
        p.add_argument("-q", "--quiet", action="store_true",
                       help="no progress lines on stderr, only the answer and errors")
        p.add_argument("-v", "--verbose", action="store_true",
                       help="also the details of every stage (solver messages)")
        p.add_argument("--time-limit", type=_seconds, metavar="SECONDS",
                       help="stop after SECONDS with status time_limit (exit 3)")
        p.set_defaults(run=run)
    return parser


def _version() -> str:
    from mitld_lp import __version__

    return __version__


class _StageLines(logging.Handler):
    """The library's log records as one printable line each on stderr; remembers the
    last one so that a stop can say where it happened."""

    def __init__(self) -> None:
        super().__init__()
        self.last = ""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.last = printable(record.getMessage())
            print(f"{PROG}: {self.last}", file=sys.stderr, flush=True)
        except Exception:  # noqa: BLE001 - logging must never break the command
            self.handleError(record)


def _run(args: argparse.Namespace) -> int:
    """Run the verb; map every exception to an exit code and one line on stderr."""
    try:
        return args.run(args)
    except _BUDGET_STOPS as err:  # before the user errors: some budgets subclass them
        _say(f"stopped: {err}")
        return EXIT_UNCERTIFIED
    except _USER_ERRORS as err:
        _say(f"error: {err}")
        return EXIT_USAGE
    except BrokenPipeError:  # the reader (e.g. `| head`) went away: not an error
        sys.stderr.close()
        return EXIT_OK
    except MemoryError:
        _say("stopped: out of memory (lower --max-states, or give the machine more memory)")
        return EXIT_UNCERTIFIED
    except Exception as err:  # noqa: BLE001 - the CLI never shows a traceback
        first = str(err).splitlines()[0] if str(err) else ""
        _say(f"internal error: {type(err).__name__}: {first} (please report this)")
        return EXIT_INTERNAL


def _say(message: str) -> None:
    print(f"{PROG}: {printable(message)}", file=sys.stderr, flush=True)


_WATCHDOG_GRACE = 1.0
"""Seconds past ``--time-limit`` before the command is stopped from outside."""

#: The thread running the current command, if it is still running after ``main`` has
#: returned (interrupted or out of time): :func:`run` then ends the process at once.
_worker: threading.Thread | None = None


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``); return the exit status.

    The command runs in a worker thread while this thread waits, so that Ctrl-C and
    ``--time-limit`` take effect within a tenth of a second whatever the stage is doing
    (the numerical kernels release the interpreter lock)."""
    global _worker
    try:
        args = _build_parser().parse_args(argv)
    except UsageError as err:
        _say(f"error: {err}")
        return EXIT_USAGE
    except SystemExit as stop:  # --help and --version have printed and exit 0
        return stop.code if isinstance(stop.code, int) else EXIT_USAGE
    args.started = time.monotonic()
    cancelled = threading.Event()
    handler = _StageLines()
    package_log = logging.getLogger("mitld_lp")
    if not args.quiet:
        package_log.addHandler(handler)
        package_log.setLevel(logging.DEBUG if args.verbose else logging.INFO)
    outcome: list[int] = []

    def work() -> None:
        _command.cancelled = cancelled
        outcome.append(_run(args))

    worker = threading.Thread(target=work, name=PROG, daemon=True)
    # The solvers get the limit itself and answer with a status; the watchdog stops a
    # stage that cannot (the product, a native call) shortly after it.
    deadline = None if args.time_limit is None else (
        args.started + args.time_limit + _WATCHDOG_GRACE)
    try:
        worker.start()
        while worker.is_alive():
            worker.join(0.1)
            if deadline is not None and time.monotonic() >= deadline and worker.is_alive():
                where = f" (last stage: {handler.last})" if handler.last else ""
                if getattr(args, "json", False):
                    print(_dumps({"status": "time_limit", "time_limit": args.time_limit}),
                          flush=True)
                cancelled.set()
                _say(f"stopped: time limit of {args.time_limit:g} s reached{where}")
                _worker = worker
                return EXIT_UNCERTIFIED
    except KeyboardInterrupt:
        cancelled.set()
        _say("interrupted")
        _worker = worker
        return EXIT_INTERRUPTED
    finally:
        package_log.removeHandler(handler)
    return outcome[0] if outcome else EXIT_INTERNAL


def run() -> None:
    """The ``mitld-lp`` console script: :func:`main`, then exit at once if the command's
    thread is still busy (interrupted or out of time)."""
    code = main()
    if _worker is not None and _worker.is_alive():
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":
    run()

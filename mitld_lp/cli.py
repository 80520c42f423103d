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

from mitld_lp import defaults, files, watch
from mitld_lp.arguments import bounded_int, memory_size, probability_budget, seconds, solver_name
from mitld_lp.automata.translate import AutomatonTooLarge, TranslationError
from mitld_lp.distributions import DistributionError
from mitld_lp.logic.fragment import FragmentError, FragmentReport, check
from mitld_lp.logic.parser import ParseError, parse_source
from mitld_lp.model import ModelError
from mitld_lp.product import ProductTooLarge
from mitld_lp.sweep.spec import SweepError
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
    files.OutputPathError,
    FileExistsError,
    SweepError,
)

#: Exceptions that mean "a budget stopped the work" (exit 3).
_BUDGET_STOPS: tuple[type[Exception], ...] = (ProductTooLarge, AutomatonTooLarge)

#: 3: no certified answer (a solver status or a budget stop; the status is printed).
EXIT_OK, EXIT_INTERNAL, EXIT_USAGE, EXIT_UNCERTIFIED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130


# --------------------------------------------------------------------------- output files


def _output_path(given: str, force: bool, what: str, suffixes: tuple[str, ...] = ()) -> Path:
    """Check, before any work, that ``given`` can be written (the one rule,
    :func:`mitld_lp.files.writable_path`)."""
    return files.writable_path(given, overwrite=force, suffixes=suffixes, what=what,
                               force="--force")


_DOT_SUFFIXES = (".dot", ".gv")


def _write(path: Path, write: Callable[[Path], object]) -> None:
    """Run ``write(path)`` (a writer of :mod:`mitld_lp.files`, which replaces the file
    only once it is complete); an OS error (disk full, no permission) is a one-line
    error."""
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


def _prob(x: float) -> str:
    """A probability for text output: 7 decimals, or 7 significant digits below 1e-3."""
    return f"{x:.7f}" if x == 0 or abs(x) >= 1e-3 else f"{x:.7g}"


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
    p.add_argument("--max-states", type=bounded_int(1), default=defaults.MAX_AUTOMATON_STATES,
                   metavar="N", help="refuse automata with more states (checked while it "
                                     "is built; exit 3)")


def _cmd_dta(args: argparse.Namespace) -> int:
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


def _count(n: int, noun: str) -> str:
    """``n`` with ``noun`` in the singular or plural: "1 clock", "2 clocks"."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


# --------------------------------------------------------------------------- model verbs


def _args_model(p: argparse.ArgumentParser, many: bool = False) -> None:
    if many:
        p.add_argument("model", nargs="+", help="model files or glob patterns (a batch: "
                       "one line per model)")
    else:
        p.add_argument("model", help="a model file (models/*.toml)")
    p.add_argument("--epsilon", type=probability_budget,
                   help="truncation budget in (0, 1) (default: the model's)")
    p.add_argument(
        "--no-clock-reduction",
        action="store_true",
        help="give every event an age clock, truncated as in the paper",
    )
    p.add_argument("--max-states", type=bounded_int(1), default=defaults.MAX_STATES,
                   metavar="N", help="refuse products (and automata) larger than N states "
                                     "(exit 3)")
    p.add_argument("--max-world-states", type=bounded_int(1), default=defaults.MAX_STATES,
                   metavar="N", help="refuse a world (a PRISM program) whose exploration "
                                     "passes N states (exit 3)")
    p.add_argument("--max-automaton-states", type=bounded_int(1),
                   default=defaults.MAX_AUTOMATON_STATES, metavar="N",
                   help="refuse automata larger than N states (exit 3)")
    p.add_argument("--max-memory", type=memory_size, metavar="SIZE",
                   help="refuse products needing more memory, e.g. 4G or 500M "
                        "(default: half the machine's memory; exit 3)")


def _build(args: argparse.Namespace) -> tuple[Model, Built]:
    """Model file -> (model, its automaton, STA and product MDP)."""
    from mitld_lp.model import load_model
    from mitld_lp.synthesis import build_product

    model = load_model(args.model, max_states=args.max_world_states,
                       max_memory=args.max_memory)
    built = build_product(
        model.game, model.spec, model.distributions,
        epsilon=model.epsilon if args.epsilon is None else args.epsilon,
        clock_reduction=not args.no_clock_reduction, max_states=args.max_states,
        max_automaton_states=args.max_automaton_states, max_memory=args.max_memory,
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
    _args_model(p, many=True)
    p.add_argument("--method", choices=("lp", "vi"), default="lp")
    p.add_argument("--solver", type=solver_name, default=defaults.SOLVER,
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
    if len(args.model) > 1 or _runs().is_pattern(args.model[0]):
        return _runs().solve_batch(args)
    args.model = args.model[0]
    policy_file = None if args.policy is None else _output_path(
        args.policy, args.force, "--policy", files.POLICY_SUFFIXES)
    model = load_model(args.model, max_states=args.max_world_states,
                       max_memory=args.max_memory)
    if _constrained().wanted(args, model):
        return _constrained().solve(args, model, policy_file)
    r = _constrained().unconstrained(
        synthesize(model, **_runs().solve_settings(args).synthesize_kwargs()), "solve")
    summary = r.summary()
    if policy_file:
        _write(policy_file, lambda p: files.write_policy(r, p, overwrite=True))
        summary["policy_file"] = str(policy_file)
    if args.json:
        _out(_dumps(summary))
    else:
        _out(f"model:        {model.name}  ({model.spec})")
        if summary.get("robust"):
            _out("robust:       worst case over the bands " + ", ".join(
                f"{e} ~ {law} (hazard at step 1 in [{_prob(h[0])}, {_prob(h[1])}])"
                for (e, law), h in zip(summary["bands"].items(),
                                       summary["first_step_hazards"].values(), strict=True)))
        _out(f"optimum in:   [{_prob(r.lower)}, {_prob(r.upper)}]"
              f"  (epsilon achieved {r.sta.epsilon_achieved:.3g})")
        _out(f"value:        {_prob(r.lower_model.value)}  ({r.method}, status {r.status.value})")
        _out("certified:    " + ("yes" if r.certified else "NO"))
        for c in r.failed_checks:
            _out(f"  failed: {c.name}: {c.detail}")
        _out(f"sizes:        {r.dta.n_states} automaton states, {r.mdp.n_states} states,"
             f" {r.mdp.n_choices} choices, {r.mdp.n_transitions} transitions")
        if r.sta.truncation_points:
            _out(f"truncation:   {r.sta.truncation_points}")
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


def _runs() -> Any:
    """The verbs over many runs (batches, sweeps, plots), imported when used."""
    from mitld_lp import cli_runs

    return cli_runs


def _export() -> Any:
    """The export verb (LP, DRN, interval DRN), imported when used."""
    from mitld_lp import cli_export

    return cli_export


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
    ("export", "write the LP (MPS/LP) and the MDP (Storm DRN)",
     lambda p: _export().args_export(p), lambda a: _export().cmd_export(a)),
    ("simulate", "Monte-Carlo rollouts of the synthesised controller",
     lambda p: _runs().args_simulate(p), lambda a: _runs().cmd_simulate(a)),
    ("sweep", "solve a model at every point of a sweep, into a results file",
     lambda p: _runs().args_sweep(p), lambda a: _runs().cmd_sweep(a)),
    ("plot", "draw a grid world's policy, or a column of a sweep's results",
     lambda p: _runs().args_plot(p), lambda a: _runs().cmd_plot(a)),
    ("pareto", "the certified curve of success probability against steps, cost or a risk",
     lambda p: _constrained().args_pareto(p), lambda a: _constrained().cmd_pareto(a)),
]


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: a bad argument raises :class:`UsageError`."""

    def error(self, message: str) -> NoReturn:  # type: ignore[override]
        if self.prog == PROG and "required: VERB" in message:  # bare `mitld-lp`
            message = "give a command: " + ", ".join(v for v, *_ in _VERBS)
        where = "" if self.prog == PROG else f"{self.prog}: "  # the line says PROG once
        raise UsageError(f"{where}{message} (see {self.prog} --help)")


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
        p.add_argument("--time-limit", type=seconds, metavar="SECONDS",
                       help="stop after SECONDS with status time_limit (exit 3)")
        p.set_defaults(run=run)
    return parser


def _version() -> str:
    from mitld_lp import __version__

    return __version__


class _StageLines(logging.Handler):
    """Log records as printable lines on stderr; the last one says where a stop was."""

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
    except files.WriteAbandoned:  # interrupted from outside, which has said so
        return EXIT_INTERRUPTED
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
    outcome: list[int] = []

    def work() -> None:
        _command.cancelled = cancelled
        outcome.append(_run(args))

    worker = threading.Thread(target=work, name=PROG, daemon=True)
    handler = _StageLines()  # this command's lines only, not an abandoned one's
    handler.addFilter(lambda record: record.thread == worker.ident)
    package_log = logging.getLogger("mitld_lp")
    if not args.quiet:
        package_log.addHandler(handler)
        package_log.setLevel(logging.DEBUG if args.verbose else logging.INFO)
    # The solvers get the limit itself and answer with a status; the watchdog stops a
    # stage that cannot (the product, a native call) shortly after it.
    deadline = None if args.time_limit is None else (
        args.started + args.time_limit + _WATCHDOG_GRACE)
    try:
        worker.start()
        while worker.is_alive():
            worker.join(0.1)
            if deadline is not None and time.monotonic() >= deadline and worker.is_alive():
                cancelled.set()
                files.abandon(worker)
                _time_stop(args, f" (last stage: {handler.last})" if handler.last else "")
                watch.report(watch.SAID)
                _worker = worker
                return EXIT_UNCERTIFIED
    except KeyboardInterrupt:
        cancelled.set()
        files.abandon(worker)  # a file half written is removed; the old one stays
        _say("interrupted")
        watch.report(watch.SAID)
        _worker = worker
        return EXIT_INTERRUPTED
    finally:
        package_log.removeHandler(handler)
    return outcome[0] if outcome else EXIT_INTERNAL


def _limited(argv: list[str]) -> argparse.Namespace | None:
    """The arguments of a command with ``--time-limit`` (None without one, when the
    arguments are wrong, :func:`main` says so, and for ``sweep``, whose worker processes
    a killed parent would leave running: its points have their own limits)."""
    if "--time-limit" not in " ".join(argv):
        return None
    try:
        args = _build_parser().parse_args(argv)
    except (UsageError, SystemExit):
        return None
    return args if args.time_limit is not None and args.verb != "sweep" else None


def _time_stop(args: argparse.Namespace, where: str) -> None:
    """The time-limit stop: the JSON status with ``--json``, and the stop line."""
    if getattr(args, "json", False):
        print(_dumps({"status": "time_limit", "time_limit": args.time_limit}), flush=True)
    _say(f"stopped: time limit of {args.time_limit:g} s reached{where}")


def run() -> None:
    """The ``mitld-lp`` console script: :func:`main`, then exit at once if interrupted
    or out of time (its thread may be in a native call the shutdown would abort)."""
    import signal

    signal.signal(signal.SIGINT, signal.default_int_handler)  # the import's handler ends
    limited = _limited(sys.argv[1:])
    if limited is not None:  # the limit is kept from a parent process (watch.py)
        code = watch.watched(limited.time_limit, lambda: _time_stop(
            limited, " (inside a long native call)"))
        if code is not None:
            sys.exit(code)
    try:
        code = main()
    except KeyboardInterrupt:  # before the command started (reading the arguments)
        _say("interrupted")
        code = EXIT_INTERRUPTED
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # done: a late Ctrl-C changes nothing
    if _worker is not None:  # interrupted or out of time: no finalisation under a thread
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":
    run()

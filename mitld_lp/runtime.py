"""Run a saved controller with NumPy alone: no SciPy, cvxpy, Clarabel, lark or stormpy.

    from mitld_lp.runtime import load
    controller = load("bus.npz")          # any kind (a randomised one: seed=...)
    action = controller.act((0, 0))       # step 0: no events yet
    action = controller.act((1, 0), {"b1"})
    ...                                   # None once the task is decided

A controller that acts on sensor reports takes them as ``act(state, reports={"b2"})``.
The file is read by :mod:`mitld_lp.controllers.reader` and stepped by
:class:`~mitld_lp.controllers.stepper.Stepper`, the step rule of every controller of the
library too (:class:`mitld_lp.Controller`, :class:`mitld_lp.ConstrainedController`, the
sensed one), so the runtime and the library cannot disagree.  Those modules import only
the standard library and NumPy (``import mitld_lp`` itself loads its modules lazily),
so a robot's process starts in a fraction of the full package's time.

:func:`serve` is the line loop behind ``mitld-lp run CONTROLLER``: one JSON object per
line on its input, ``{"state": ..., "events": [...]}`` (the world state as the policy
table writes it; the events seen in the step that led there; ``"reports": [...]``, the
sensors' reports, for a controller that acts on them), one ``{"action": ...}``
per line on its output (``null`` once the task is decided; ``"status"`` says how).  A
line longer than :data:`LINE_BUDGET` characters is not kept: it is answered with an
error, its rest read and dropped in pieces, and the loop goes on.

:func:`main` is that command itself, ``mitld-lp run CONTROLLER [--seed S]`` (the
console script hands ``run`` to it before it imports anything of the command line,
:func:`mitld_lp.startup.command`) and ``python -m mitld_lp.runtime CONTROLLER``: the one
command line outside :mod:`mitld_lp.cli`, so that it too runs with NumPy alone.
"""

from __future__ import annotations

import argparse
import io
import json
import sys
from collections.abc import Hashable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

from mitld_lp.controllers.format import (
    ACCEPTED,
    FORMAT,
    KEEP,
    REJECTED,
    UNDECIDED,
    VERSION,
    ControllerFileError,
    decode_state,
    encode_state,
    quoted,
)
from mitld_lp.controllers.reader import read as read_plan
from mitld_lp.controllers.stepper import Decision, Stepper
from mitld_lp.controllers.tables import SavedPlan, SensedPlan, advance

__all__ = [
    "ACCEPTED",
    "ControllerFileError",
    "Decision",
    "FORMAT",
    "KEEP",
    "REJECTED",
    "RuntimeController",
    "SavedPlan",
    "SensedPlan",
    "Stepper",
    "UNDECIDED",
    "VERSION",
    "advance",
    "decode_state",
    "encode_state",
    "LINE_BUDGET",
    "load",
    "main",
    "read_plan",
    "run_file",
    "serve",
]

LINE_BUDGET = 1 << 20
"""The longest observation line :func:`serve` reads, in characters (1 MiB; an
observation of a PRISM state with a hundred variables by name takes a few KB): a longer
line is answered with an error and never held whole in memory."""

PROG = "mitld-lp"


def _printable(text: str) -> str:
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


# --------------------------------------------------------------------------- the controller


class RuntimeController(Stepper):
    """A saved controller run from its tables, of any kind: ``act(state, events,
    reports)``."""

    def __init__(self, plan: SavedPlan | SensedPlan, *, seed: int | None = 0) -> None:
        self._begin(plan, np.random.default_rng(seed))

    @property
    def plan(self) -> SavedPlan | SensedPlan:
        assert isinstance(self._plan, SavedPlan | SensedPlan)
        return self._plan

    @property
    def status(self) -> str:
        return self.status_name

    def reset(self, seed: int | None = None) -> None:
        """Start a new run; with ``seed``, a new generator (else the generator runs on)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        self._restart()

    def act(self, state: Hashable, events: Iterable[str] = (),
            reports: Iterable[str] = ()) -> str | None:
        """The action in world ``state`` after the ``events`` seen and the sensors'
        ``reports`` received in the step that led there; None once decided."""
        return self._step(state, _names(events, "events"), _names(reports, "reports"))

    def world_state(self, value: Any) -> Hashable:
        """The world state that ``value`` (as the policy table writes it: a list for a
        tuple, an object of variables for a PRISM world) stands for."""
        variables = self.plan.variables
        if isinstance(value, dict):
            if variables is None:
                raise ValueError(f"state {quoted(value)}: this world's states have no "
                                 "variable names; give the state as the policy table does")
            missing = [v for v in variables if v not in value]
            extra = sorted(set(value) - set(variables))
            if missing or extra:
                raise ValueError(f"state {quoted(value)}: expected the variables "
                                 f"{', '.join(variables)}")
            value = [value[v] for v in variables]
        return decode_state(value)


def _names(values: Iterable[str], field: str) -> frozenset[str]:
    if isinstance(values, str | bytes):
        raise TypeError(f"{field}: expected a set of event names, got the string {values!r}")
    return frozenset(values)


def load(path: str | Path, *, seed: int | None = 0) -> RuntimeController:
    """The controller saved at ``path`` (deterministic, randomised or sensed), ready at
    step 0 (a randomised one draws from a generator seeded with ``seed``).
    :class:`ControllerFileError` if it is not one."""
    return RuntimeController(read_plan(path), seed=seed)


# --------------------------------------------------------------------------- the line loop


def serve(controller: RuntimeController, lines: Iterable[str] | IO[str], out: IO[str],
          *, budget: int = LINE_BUDGET) -> int:
    """Answer each JSON observation of ``lines`` with one JSON line on ``out`` (module
    docstring).  An observation with ``"reset": true`` starts a new run first.  A bad
    line is answered with ``{"error": ...}`` naming its line number, and the loop goes
    on; so is a line longer than ``budget`` characters (from a stream, such as standard
    input, it is read ``budget`` characters at a time and dropped, never held whole).
    Returns how many lines were bad."""
    bad = 0
    for number, line in enumerate(_bounded(lines, budget), 1):
        if line is not None and not line.strip():
            continue
        try:
            if line is None:
                raise ValueError(f"longer than {budget:,} characters, the most an "
                                 "observation line may have; the line was skipped")
            reply = _answer(controller, line)
        except (ValueError, TypeError, RecursionError) as exc:
            bad += 1
            reply = {"error": f"line {number}: {_printable(str(exc))[:300]}"}
        out.write(json.dumps(reply) + "\n")
        out.flush()
    return bad


def _bounded(lines: Iterable[str] | IO[str], budget: int) -> Iterator[str | None]:
    """The lines of ``lines`` (each at most ``budget`` characters before its newline),
    None for a longer one; from a stream, with at most ``budget + 1`` characters in
    memory (the rest of a longer line is read and dropped)."""
    readline = getattr(lines, "readline", None)
    if readline is None:  # an iterable of lines, already in memory: held to the budget
        for line in lines:
            yield line if len(line) - line.endswith("\n") <= budget else None
        return
    while line := readline(budget + 1):
        if len(line) <= budget or line.endswith("\n"):
            yield line
            continue
        while (rest := readline(budget)) and not rest.endswith("\n"):
            pass
        yield None


def _answer(controller: RuntimeController, line: str) -> dict[str, Any]:
    try:
        o = json.loads(line)
    except ValueError as exc:
        raise ValueError(f"not JSON ({exc})") from None
    if not isinstance(o, dict):
        raise ValueError('expected an object {"state": ..., "events": [...]}')
    extra = sorted(set(o) - {"state", "events", "reports", "reset"})
    if extra:
        raise ValueError(f"unknown key {extra[0]!r} (keys: state, events, reports, reset)")
    if "state" not in o:
        raise ValueError('no "state": expected {"state": ..., "events": [...]}')
    seen = {field: o.get(field, []) for field in ("events", "reports")}
    for field, names in seen.items():
        if not isinstance(names, list) or not all(isinstance(e, str) for e in names):
            raise ValueError(f"{field}: expected a list of event names")
    if o.get("reset", False) is True:
        controller.reset()
    state = controller.world_state(o["state"])
    action = controller.act(state, seen["events"], seen["reports"])
    return {"action": action, "status": controller.status}


# --------------------------------------------------------------------------- the command


class _Usage(Exception):
    """A bad argument (argparse's message)."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> Any:  # one line, as the command line says it
        raise _Usage(message)


def _parser(prog: str) -> argparse.ArgumentParser:
    p = _Parser(
        prog=prog, description="Answer JSON observations on stdin, one per line "
        '({"state": ..., "events": [...]}), with a saved controller\'s actions on stdout.')
    p.add_argument("controller", metavar="CONTROLLER",
                   help="a controller file saved by Controller.save / export --controller")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of a randomised controller's generator (default 0)")
    p.add_argument("-q", "--quiet", action="store_true", help="(nothing is said but errors)")
    p.add_argument("-v", "--verbose", action="store_true", help="(nothing more to say)")
    return p


def main(argv: Sequence[str] | None = None, prog: str = f"{PROG} run") -> int:
    """The command ``mitld-lp run CONTROLLER [--seed S]`` (:func:`run_file`); a bad
    argument is refused with the usage and exit 2, ``--help`` prints it."""
    try:
        args = _parser(prog).parse_args(argv)
    except _Usage as bad:
        return _error(sys.stderr, f"{bad} (see {prog} --help)")
    except SystemExit as stop:  # --help has printed the usage
        return int(stop.code or 0)
    return run_file(args.controller, seed=args.seed)


def run_file(path: str | Path, *, seed: int = 0, stdin: IO[str] | None = None,
             stdout: IO[str] | None = None, stderr: IO[str] | None = None) -> int:
    """Serve the controller saved at ``path`` on ``stdin`` / ``stdout`` (default the
    process's; its input read as UTF-8, a bad byte replaced); exit 0, or 2 when the file
    is not a controller or some line was bad (one line on ``stderr`` says so)."""
    err = sys.stderr if stderr is None else stderr
    if seed < 0:
        return _error(err, f"--seed: must be >= 0, got {seed}")
    try:
        controller = load(path, seed=seed)
    except ControllerFileError as exc:
        return _error(err, str(exc))
    raw = getattr(sys.stdin, "buffer", None) if stdin is None else None
    text = io.TextIOWrapper(raw, encoding="utf-8", errors="replace") if raw else None
    try:
        bad = serve(controller, stdin or text or sys.stdin,
                    sys.stdout if stdout is None else stdout)
    finally:
        if text is not None:
            text.detach()  # standard input stays open for whoever reads it next
    if bad:
        return _error(err, f"run: {bad} observation line{'s' if bad > 1 else ''} could not "
                      "be answered (each got an error line)")
    return 0


def _error(err: IO[str], message: str) -> int:
    err.write(f"{PROG}: error: {_printable(message)}\n")
    err.flush()
    return 2


if __name__ == "__main__":  # python -m mitld_lp.runtime CONTROLLER
    sys.exit(main(prog="python -m mitld_lp.runtime"))

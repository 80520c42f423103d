"""What is checked on a PRISM program before Storm builds it, and Storm's output made quiet.

* :func:`check_program`: every variable has a non-empty range that contains its initial
  value, and every command whose probabilities are constants has probabilities in
  [0, 1] summing to 1 (within PRISM's :data:`SUM_TOLERANCE`); it returns the
  :class:`SizeBound` of the program, ``prod over the variables of |range|``, an upper
  bound on the states Storm can reach, known before anything is built (a note, not a
  refusal: the reachable part is often far smaller).
* :func:`storm_error`: one of Storm's exceptions as one line naming the file, and the
  line, the module and the command where Storm's message allows it (a parse error
  quotes at most :data:`EXCERPT` characters of the file).
* :func:`storm_quiet`: Storm's C++ logger writes to the process's standard output; this
  sends file descriptor 1 elsewhere during a Storm call, so that nothing but the
  program's answer reaches stdout (the lines go to the debug log).

Every error is a :class:`mitld_lp.worlds.WorldError`, one line.
"""

from __future__ import annotations

import contextlib
import logging
import math
import re
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

from mitld_lp.util.quiet import native_quiet
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.prism_depth import ExpressionDepth

__all__ = [
    "SizeBound", "check_program", "storm_error", "storm_quiet", "excerpt", "EXCERPT",
    "SUM_TOLERANCE", "show_sum", "storm_sum", "check_constants", "parse_program",
    "extra_labels", "with_labels", "builder_options", "with_constants", "storm_build",
    "labelled_program",
]

log = logging.getLogger("mitld_lp.worlds.prism")

EXCERPT = 24
"""At most this many characters of a user's file are quoted in a message."""

SUM_TOLERANCE = 1e-5
"""How far from 1 the probabilities of a command may sum: PRISM's default
(``-sumroundoff``, an absolute difference), so that a file PRISM reads is read here
(``1/3`` written three times, ``0.8 + 0.1 + 0.1`` in floating point).  A larger excess or
shortfall is refused with the sum."""

_UNSET = "__storm::notinitialized__"  # Storm's text for an expression that is not given


def show_sum(total: float | Fraction) -> str:
    """A sum of probabilities with the digits that tell it from 1: the shortest decimal
    that reads back as the same double (``0.9``, ``0.99999``, ``1.0000001``), and an
    exact fraction as well when it is not a short decimal (``2/3`` is ``0.6666666666666666``)."""
    text = repr(float(total))
    if isinstance(total, Fraction) and Fraction(text) != total:
        return f"{text} ({total.numerator}/{total.denominator})"
    return text


def storm_sum(text: str) -> Fraction | None:
    """The sum in one of Storm's messages on probabilities that do not sum to 1
    (``actually sum to 9/10``), or None."""
    m = re.search(r"actually sum to (-?[0-9./e+-]+)\)", text)
    if not m:
        return None
    try:
        return Fraction(m[1])
    except (ValueError, ZeroDivisionError):
        return None


def excerpt(text: str, limit: int = EXCERPT) -> str:
    """``text`` on one line, cut to ``limit`` characters (``...`` marks a cut)."""
    flat = " ".join(text.split())
    return flat if len(flat) <= limit else flat[: limit - 3] + "..."


# --------------------------------------------------------------------------- the program


@dataclass(frozen=True, slots=True)
class SizeBound:
    """``states = prod over variables v of values(v)``: every state Storm builds is a
    valuation of the program's variables (a variable no command assigns is a constant
    to Storm and counts once), so no more than ``states`` are reachable.

    Attributes:
        states: the bound.
        factors: ``(variable, number of values)``, largest first.
    """

    states: int
    factors: tuple[tuple[str, int], ...]

    def __str__(self) -> str:
        shown = [f"{name}: {n:,}" for name, n in self.factors[:4]]
        more = len(self.factors) - len(shown)
        rest = f" x {more} more" if more > 0 else ""
        product = " x ".join(shown) if shown else "no variables"
        return f"at most {self.states:,} states from the variables' ranges ({product}{rest})"


def _owner(module: Any | None) -> str:
    return f"module {module.name}" if module is not None else "global"


def _constant(expr: Any, what: str, where: str) -> int:
    if expr.contains_variables():
        raise WorldError(f"{where}: {what} ({excerpt(str(expr))}) must be a constant")
    return int(expr.evaluate_as_int())


def _integer_variables(program: Any) -> list[tuple[Any | None, Any]]:
    """``(module or None for a global, variable)`` for every integer variable."""
    owned = [(None, v) for v in program.global_integer_variables]
    return owned + [(m, v) for m in program.modules for v in m.integer_variables]


def _range(program: Any, name: str) -> str:
    """``[lo..hi]`` of the integer variable ``name`` ('' if it has none)."""
    for _, var in _integer_variables(program):
        low, high = var.lower_bound_expression, var.upper_bound_expression
        if var.name == name and _UNSET not in (str(low), str(high)):
            with contextlib.suppress(RuntimeError):
                return f" [{low.evaluate_as_int()}..{high.evaluate_as_int()}]"
    return ""


def _check_variables(program: Any, where: str) -> list[tuple[str, int]]:
    """Each variable's number of values; refuses empty ranges and initial values out of
    range (Storm reports neither with the variable's name)."""
    factors: list[tuple[str, int]] = []
    checked_init = not program.has_initial_states_expression
    for module, var in _integer_variables(program):
        at = f"{where}: {_owner(module)}: variable {var.name!r}"
        if _UNSET in (str(var.lower_bound_expression), str(var.upper_bound_expression)):
            raise WorldError(
                f"{at} has no range; give it one ({var.name} : [lo..hi]) so that the states "
                "are bounded before Storm builds them"
            )
        low = _constant(var.lower_bound_expression, "its lower bound", at)
        high = _constant(var.upper_bound_expression, "its upper bound", at)
        if low > high:
            raise WorldError(f"{at}: its range [{low}..{high}] is empty")
        init = var.initial_value_expression
        if checked_init and str(init) != _UNSET and not init.contains_variables():
            value = int(init.evaluate_as_int())
            if not low <= value <= high:
                raise WorldError(
                    f"{at}: initial value {value} is outside its range [{low}..{high}]"
                )
        factors.append((var.name, high - low + 1))
    booleans = list(program.global_boolean_variables)
    booleans += [v for m in program.modules for v in m.boolean_variables]
    factors += [(v.name, 2) for v in booleans]
    return factors


def command_label(module: Any, k: int, command: Any) -> str:
    """``module m, command 2 ([go] x<3 -> ...)``: how a message names a command."""
    return f"module {module.name}, command {k} ({excerpt(str(command), 40)})"


def _check_probabilities(program: Any, where: str) -> None:
    """Commands whose update probabilities are constants: each in [0, 1], total 1.
    (Storm checks the others state by state while it builds.)"""
    for module in program.modules:
        for k, command in enumerate(module.commands, start=1):
            probabilities = [u.probability_expression for u in command.updates]
            if any(p.contains_variables() for p in probabilities):
                continue
            values = [Fraction(str(p.evaluate_as_rational())) for p in probabilities]
            at = f"{where}: {command_label(module, k, command)}"
            for p in values:
                if not 0 <= p <= 1:
                    raise WorldError(f"{at}: probability {float(p):g} is not in [0, 1]")
            total = sum(values, Fraction(0))
            if abs(total - 1) > SUM_TOLERANCE:
                raise WorldError(f"{at}: probabilities sum to {show_sum(total)}, not 1")


def check_program(program: Any, where: str) -> SizeBound:
    """Check ``program`` (constants substituted) and bound its states (module doc).

    Raises :class:`WorldError` naming the module, variable or command."""
    factors = _check_variables(program, where)
    _check_probabilities(program, where)
    factors.sort(key=lambda f: -f[1])
    return SizeBound(states=math.prod(n for _, n in factors), factors=tuple(factors))


# --------------------------------------------------------------------------- Storm's errors


_CLASS = re.compile(r"^\s*[A-Za-z]+Exception:\s*")
_PARSE = re.compile(r"Parsing error at (\d+):(\d+):\s*(.*?),?\s*here:[ \t]*\n\t?([^\n]*)")
_AT_LINE = re.compile(r"^Error in .*?, line (\d+):\s*(.*)$")
_OUT_OF_RANGE = re.compile(
    r"^The update (.*) leads to an out-of-bounds value \((-?\d+)\) for the variable '(\w+)'"
)
_SUM = re.compile(r"^Probabilities do not sum to one for command '(.*)' \(actually sum to (\S+)\)")
_SYNC_SUM = re.compile(
    r"^Sum of update probabilities do not \w+ to one .*\(actually sum to (\S+)\)"
)
_NEGATIVE = re.compile(r"negative probabilities in '(.*)'")


def _finder(program: Any, shown: Any) -> Callable[[Callable[[Any], bool]], str]:
    """``find(want)``: ``"<command label>: "`` of the first command of ``program`` that
    ``want`` accepts, quoted from ``shown`` (the same commands as the user wrote them);
    ``""`` if there is none."""

    def find(want: Callable[[Any], bool]) -> str:
        for i, module in enumerate(program.modules):
            for k, command in enumerate(module.commands, start=1):
                if want(command):
                    original = shown.modules[i]
                    return f"{command_label(original, k, original.commands[k - 1])}: "
        return ""

    return find


def storm_error(
    exc: BaseException, where: str, program: Any = None, shown: Any = None
) -> WorldError:
    """Storm's exception ``exc`` as a :class:`WorldError` of one line.

    A parse error becomes ``FILE:LINE:COLUMN: PRISM parse error: expecting X at "..."``
    (an excerpt of the file at the position); ``Error in FILE, line N: ...`` becomes
    ``FILE:N: ...``; an update out of a variable's range and probabilities that do not
    sum to 1 name the module and command of ``program`` (the program Storm was
    building), quoted from ``shown`` (default ``program``): the same commands before
    commands without an action were given one.  Anything else is Storm's first line,
    cut to a reasonable length."""
    text = _CLASS.sub("", str(exc).strip())
    m = _PARSE.search(text)
    if m:
        line, column, reason, quoted = int(m[1]), int(m[2]), m[3].strip(), m[4]
        near = quoted[column - 1 :] if 0 < column <= len(quoted) + 1 else quoted
        at = f" at {excerpt(near)!r}" if near.strip() else " at the end of the line"
        return WorldError(f"{where}:{line}:{column}: PRISM parse error: {reason}{at}")
    first = text.splitlines()[0] if text else type(exc).__name__
    m = _AT_LINE.match(first)
    if m:
        return WorldError(f"{where}:{m[1]}: {excerpt(m[2], 200)}")
    if program is not None:
        find = _finder(program, program if shown is None else shown)
        m = _OUT_OF_RANGE.match(first)
        if m:
            update, value, name = m[1], m[2], m[3]
            at = find(lambda c: any(str(u) == update for u in c.updates))
            return WorldError(
                f"{where}: {at}an update gives {name!r} the value {value}, outside its "
                f"range{_range(program, name)}"
            )
        m = _SUM.match(first)
        if m:
            at = find(lambda c, text=m[1]: str(c) == text)
            total = storm_sum(first)
            shown = m[2] if total is None else show_sum(total)
            return WorldError(f"{where}: {at}probabilities sum to {shown} in a state, not 1")
        m = _SYNC_SUM.match(first)
        if m:
            total = storm_sum(first)
            shown = m[1] if total is None else show_sum(total)
            return WorldError(
                f"{where}: the synchronised commands of an action have probabilities "
                f"summing to {shown} in a state, not 1"
            )
        m = _NEGATIVE.search(first)
        if m:
            at = find(
                lambda c, text=m[1]: any(str(u.probability_expression) == text for u in c.updates)
            )
            return WorldError(f"{where}: {at}a probability is negative in a state")
    return WorldError(f"{where}: Storm: {excerpt(first, 200)}")


# --------------------------------------------------------------------------- Storm's output


def storm_quiet() -> contextlib.AbstractContextManager[None]:
    """Storm's output (its logger prints errors and warnings on stdout, which must carry
    nothing but the answer) sent to the debug log: :func:`mitld_lp.util.quiet.native_quiet`."""
    return native_quiet("storm")


def check_constants(program: Any, constants: Mapping[str, Any], where: str) -> None:
    declared = {c.name: c for c in program.constants}
    for name, value in constants.items():
        if name not in declared:
            known = ", ".join(sorted(declared)) or "none"
            raise WorldError(f"{where}: constant {name!r} is not declared (constants: {known})")
        c = declared[name]
        if c.defined:
            raise WorldError(
                f"{where}: constant {name!r} already has a value in the file "
                f"({c.definition}); only undefined constants can be given"
            )
        kind = c.type
        if kind.is_boolean:
            ok, want = isinstance(value, bool), "a boolean"
        elif kind.is_integer:
            ok, want = isinstance(value, int) and not isinstance(value, bool), "an integer"
        else:
            ok = isinstance(value, int | float) and not isinstance(value, bool)
            want = "a number"
        if not ok:
            raise WorldError(f"{where}: constant {name!r} must be {want}, got {value!r}")
    missing = sorted(c.name for c in program.constants if not c.defined and c.name not in constants)
    if missing:
        raise WorldError(
            f"{where}: constants {', '.join(missing)} have no value in the file; "
            "give them with constants={...}"
        )


# --------------------------------------------------------------------------- the build


def parse_program(stormpy: Any, file: str, where: str) -> Any:
    """Storm's parse of the PRISM file ``file`` (errors name ``where``)."""
    try:
        with storm_quiet():
            return stormpy.parse_prism_program(file)
    except (RuntimeError, stormpy.exceptions.StormError) as exc:
        raise storm_error(exc, where) from None


_FORMULA = re.compile(r"^formula (\w+) = ", re.MULTILINE)


def extra_labels(program: Any, define: dict[str, str], where: str,
                 depth: ExpressionDepth | None = None) -> dict[str, str]:
    """``name -> expression`` of the labels to add: every Boolean ``formula`` of the file
    that no label shadows (``name -> name``), then ``define`` (each no deeper than
    Storm's parser takes, counted with the file's formulas: ``depth``, when given)."""
    labels = {lab.name for lab in program.labels}
    manager = program.expression_manager
    extra: dict[str, str] = {}
    for name in _FORMULA.findall(str(program)):
        if name not in labels and manager.get_variable(name).has_boolean_type():
            extra[name] = name
    for name, text in define.items():
        if not re.fullmatch(r"[A-Za-z_]\w*", name):
            raise WorldError(f"label {name!r}: not a PRISM identifier")
        if name in labels or name in extra:
            what = "label" if name in labels else "formula"
            raise WorldError(f"label {name!r}: {where} already has a {what} {name!r}")
        if not isinstance(text, str) or not text.strip() or ";" in text or '"' in text:
            raise WorldError(f"label {name!r}: must be one PRISM expression, got {text!r}")
        deep = None if depth is None else depth.deepest(text)
        if deep is not None:
            raise WorldError(f"label {name!r}: {deep.message()}")
        extra[name] = text
    return extra


def with_labels(stormpy: Any, path: Path, extra: dict[str, str], where: str) -> Any:
    """The program of ``path`` with ``label "name" = expression;`` appended for each
    entry of ``extra`` (a copy in a temporary folder; the file is not changed)."""
    text = path.read_text(encoding="utf-8")
    first = text.count("\n") + 2
    lines = [f'label "{name}" = {expression};' for name, expression in extra.items()]
    with tempfile.TemporaryDirectory(prefix="mitld-prism-") as folder:
        copy = Path(folder) / path.name
        copy.write_text(text + "\n" + "\n".join(lines) + "\n", encoding="utf-8")
        try:
            with storm_quiet():
                return stormpy.parse_prism_program(str(copy))
        except (RuntimeError, stormpy.exceptions.StormError) as exc:
            error = str(storm_error(exc, where))
    m = re.match(rf"{re.escape(where)}:(\d+):(?:\d+: )?(.*)$", error)
    if m and int(m[1]) >= first:
        name = list(extra)[min(int(m[1]) - first, len(extra) - 1)]
        raise WorldError(f"label {name!r} = {extra[name]!r}: {m[2]}")
    raise WorldError(error)


def labelled_program(stormpy: Any, path: Path, file: str, define: Mapping[str, str],
                     where: str, depth: ExpressionDepth | None = None,
                     check: Callable[[Any], None] | None = None) -> Any:
    """The program of ``path`` (read as ``file``) with the labels of
    :func:`extra_labels` added (``define``, and the Boolean formulas no label shadows),
    ``check`` called on it first (the model type): the program :func:`parse_program`,
    :func:`extra_labels` and :func:`with_labels` make, with their errors.

    With ``define`` given, Storm parses the file once, with the labels (Storm's parse is
    0.005-0.010 s of every QVBS instance's load): where that parse fails, a label is
    refused, or it names a label or a Boolean formula of the file, the file is parsed
    again as written and the steps above run, so that the errors are theirs; where the
    file has Boolean formulas to add as labels, it is parsed once more with them."""
    once = _parsed_once(stormpy, path, dict(define), where, depth) if define else None
    if once is not None:
        if check is not None:
            check(once)
        return once
    program = parse_program(stormpy, file, where)
    if check is not None:
        check(program)
    extra = extra_labels(program, dict(define), where, depth)
    return with_labels(stormpy, path, extra, where) if extra else program


def _parsed_once(stormpy: Any, path: Path, define: dict[str, str], where: str,
                 depth: ExpressionDepth | None) -> Any | None:
    """:func:`labelled_program`'s one parse, or None where the steps must run."""
    for name, text in define.items():
        if (not re.fullmatch(r"[A-Za-z_]\w*", name) or not isinstance(text, str)
                or not text.strip() or ";" in text or '"' in text
                or depth is not None and depth.deepest(text) is not None):
            return None
    try:
        program = with_labels(stormpy, path, define, where)
    except WorldError:
        return None
    names = [lab.name for lab in program.labels]
    own = names[: len(names) - len(define)]
    if names[len(own):] != list(define) or not set(own).isdisjoint(define):
        return None
    manager = program.expression_manager
    formulas = [name for name in _FORMULA.findall(str(program))
                if name not in own and manager.get_variable(name).has_boolean_type()]
    if not set(formulas).isdisjoint(define):
        return None
    if formulas:  # the labels in extra_labels' order: the formulas first
        return with_labels(stormpy, path, {**{f: f for f in formulas}, **define}, where)
    return program


def with_constants(stormpy: Any, program: Any, given: Mapping[str, Any], where: str) -> Any:
    """The program with its open constants given their values (Storm's errors name
    ``where``); the program itself when none is given."""
    if not given:
        return program
    try:
        with storm_quiet():
            return stormpy.instantiate_constants(program, dict(given))[0]
    except (RuntimeError, stormpy.exceptions.StormError) as exc:
        raise storm_error(exc, where) from None


def builder_options(stormpy: Any, program: Any, terminal: str, *, checks: bool,
                    origins: bool, valuations: bool = True, labels: bool = True) -> Any:
    """Storm's builder options for a world: every label (a label left out of the build
    would be false in every state), state valuations when ``valuations`` (a sixth of the
    build; :mod:`mitld_lp.worlds.prism_valuations`), the choice origins when ``origins``
    (they name every choice: :mod:`mitld_lp.worlds.prism_origins`), else the choice
    labels when ``labels`` (False: no choice named by this build, every one named when
    first read, :mod:`mitld_lp.worlds.prism_names`), exploration checks when ``checks``
    (without them Storm's out-of-bounds state, so that an update out of a variable's
    range stays visible), and
    no expansion past the states where ``terminal`` holds (a PRISM expression; "" for
    none)."""
    formula = None
    if terminal:
        with storm_quiet():
            formula = stormpy.parse_properties(f"Pmax=? [F {terminal}]", program)[0]
        formula = formula.get_raw_formula()
    o = stormpy.BuilderOptions([formula]) if formula is not None else stormpy.BuilderOptions()
    o.set_exploration_checks(checks)
    o.set_add_out_of_bounds_state(not checks)  # range errors kept visible
    o.set_build_all_labels()
    if origins:
        o.set_build_choice_origins()
    elif labels:
        o.set_build_choice_labels()
    if valuations:
        o.set_build_state_valuations()
    return o


def storm_build(stormpy: Any, program: Any, options: Any, value_type: Any,
                limit: int | None) -> Any:
    """Storm's sparse build of ``program`` (``value_type``: float or ``stormpy.Rational``,
    the latter without a limit), breadth first; with ``limit``, no state expanded once
    that many are found."""
    if limit is None:
        return stormpy.build_model[value_type](program, options=options)
    from stormpy import developer  # pyright: ignore[reportMissingImports]

    explore = developer.ExplicitModelBuilderOptions[float]()
    explore.exploration_order = developer.ExplorationOrder.BFS  # Storm's default order
    explore.exploration_state_limit = limit
    description = developer.SymbolicModelDescription(program)
    return developer.make_explicit_model_builder[float](
        description, options, exploration_options=explore).build()

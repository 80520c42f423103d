"""PCTL properties as PRISM and Storm users write them, read by Storm's own parser and
posed as the package's tasks.

``read_properties(program, text, where)`` parses a property (``Pmax=? [F "goal"]``) or
a properties file's text with :func:`stormpy.parse_properties` against the PRISM
program, so that labels, variables and constants mean what they mean to Storm.  The
door reads the forms posed below with our own reader first
(:mod:`mitld_lp.worlds.property_own`, the same printing and posing, no stormpy) and
comes here for the rest.
:func:`pose_property` maps one parsed property onto a task of the package, or refuses
it naming the form and the reason (:class:`PropertyError`, never another problem
answered in its place):

* ``Pmax=? [ ... ]``, ``Pmin=? [ ... ]``: the optimum, maximised or minimised;
  ``P~p [ ... ]`` with ``~`` one of ``>=``, ``>``, ``<=``, ``<``: for every scheduler,
  as Storm reads it on an MDP (the least probability for ``>=``, ``>``, the greatest
  for ``<=``, ``<``; ``Pmax>=p`` asks for the greatest), answered true or false by the
  certified bracket (:func:`verdict`);
* the path formula: ``F phi``, ``G phi``, ``X phi``, ``phi U psi``, and with a step
  bound ``F<=k``, ``F<k``, ``F[a,b]``, ``U<=k``, ``U<k``, ``U[a,b]`` (integers), which
  are MITLD's ``F``, ``G``, ``X``, ``U``, ``F[0,k]``, ``U[a,b]`` with the same step-0
  convention and the same strict until (docs/semantics.md);
* a state formula (quoted labels, Boolean expressions over the variables, ``!``, ``&``,
  ``|``): one label of the file is its proposition; anything else becomes a label of
  its own, the state formula as a PRISM expression with the file's labels written out,
  which Storm evaluates (:func:`mitld_lp.worlds.prism.load_prism`'s ``define``).

Expected rewards (``R``), expected times (``T``) and reward-bounded probabilities are
not tasks: :func:`pose_property` refuses them, and the command line's door answers
``R{"r"}min=? [F target]``, ``[C<=k]``, ``[I=k]``, ``Tmin=? [F target]`` and their
bounds ``R~b``, ``T~b`` with :mod:`mitld_lp.worlds.prism_rewards` and
:mod:`mitld_lp.exact.reward` (and :mod:`~mitld_lp.exact.horizon`),
``P=? [F{"r"}<=b target]`` with :mod:`mitld_lp.worlds.reward_bounded`.

Refused, by name: expected rewards (``R``) and times (``T``), long-run averages (``S``),
multi-objective queries, a ``filter`` other than the initial state's, ``P=?``
without ``min`` or ``max`` on an MDP (it needs one, as in Storm), a ``P`` nested in a path
formula, Boolean combinations of path formulas and nested temporal operators (LTL),
reward- and time-bounded operators, a bound with only a lower end, a bound that is not
an integer, Storm's labels ``"init"`` and ``"deadlock"``, a label the file does not
define.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

from mitld_lp.worlds import WorldError

__all__ = ["Program", "PropertyError", "Query", "read_program", "parse_constants",
           "pose_property", "read_properties", "instantiate", "verdict", "pick",
           "probability_objective", "objective_of", "refusal", "StatePoser",
           "INIT_FILTER"]


class PropertyError(WorldError):
    """A property that cannot be read, or one whose form has no faithful task (the
    message names the property, the form and why)."""


@dataclass(frozen=True)
class Query:
    """One property posed as a task.

    Attributes:
        name: the property's name in its file, or its number there (from 1).
        text: the property as Storm prints it.
        spec: the task, an MITLD formula over the file's labels and ``define``'s.
        define: labels to add, ``name -> PRISM expression`` (the state formulas that are
            not one label of the file).
        objective: ``"max"`` or ``"min"``.
        comparison: ``">="``, ``">"``, ``"<="`` or ``"<"`` for ``P~p``, else None.
        threshold: ``p`` as a fraction, for ``P~p``.
    """

    name: str
    text: str
    spec: str
    define: dict[str, str] = field(default_factory=dict)
    objective: str = "max"
    comparison: str | None = None
    threshold: Fraction | None = None


_COMPARISONS = {"GEQ": ">=", "GREATER": ">", "LEQ": "<=", "LESS": "<"}
# the values, or their maximum or minimum (QVBS's JANI files), over the initial states:
# one initial state (a world has exactly one), so its value (Storm spells it "minumum")
INIT_FILTER = re.compile(r"Obtain the (values|maximum|minimum|minumum) of the '\"init\"'-states")
_LABEL = re.compile(r'"([^"]*)"')
_NESTED = re.compile(r"(?<![\w.])(P|R|S|T|LRA)\s*(\{[^}]*\})?\s*(min|max)?\s*(=\s*\?|[<>]=?)")
_TEMPORAL = re.compile(r"(?<![\w.])[XFGUWR](?![\w])")


def parse_constants(text: str, where: str = "--const") -> dict[str, bool | int | float]:
    """``N=20,K=2,p=0.1,b=true`` (Storm's ``--constants``) as ``name -> value``: a
    boolean, an integer, or a decimal keeping its text (:class:`Written`, an exact
    answer reads ``0.1`` as ``1/10``)."""
    out: dict[str, bool | int | float] = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        name, eq, value = (s.strip() for s in item.partition("="))
        if not eq or not re.fullmatch(r"[A-Za-z_]\w*", name) or not value:
            raise PropertyError(f"{where}: {item!r} is not NAME=VALUE")
        if name in out:
            raise PropertyError(f"{where}: constant {name!r} given twice")
        if value in ("true", "false"):
            out[name] = value == "true"
        elif re.fullmatch(r"[-+]?\d+", value):
            out[name] = int(value)
        else:
            from mitld_lp.util.decimals import Written  # numpy: only for a decimal

            try:
                number = Written(value)
            except ValueError:
                number = None
            if number is None or number != number or abs(number) == float("inf"):
                raise PropertyError(f"{where}: constant {name!r}: {value!r} is not a "
                                    "number or true/false")
            out[name] = number
    return out


class Program:
    """A PRISM or JANI file, for its properties: the program (Storm's PRISM program or
    JANI model), its labels (``name -> expression``, as Storm prints it; a JANI model's
    transient Boolean variables, ``name -> name``), the constants it declares, the
    properties a JANI file carries, and the names a new proposition must not take (a
    JANI model's variables).

    A PRISM file our own parse reads (:func:`read_program`) carries its ``symbols``
    (:class:`~mitld_lp.worlds.prism_symbols.Symbols`, all our property reader needs)
    and ``storm``, the function that parses it with Storm: :attr:`program` calls it the
    first time it is read (Storm's property reader, an expected reward), not before."""

    def __init__(self, program: Any, labels: dict[str, str], constants: frozenset[str],
                 properties: tuple[Any, ...] = (), reserved: frozenset[str] = frozenset(),
                 jani: bool = False, *, symbols: Any = None,
                 storm: Callable[[], Any] | None = None) -> None:
        if program is None and storm is None:
            raise ValueError("a Program needs Storm's program or the function that parses it")
        self._program, self._storm = program, storm
        self.labels, self.constants, self.properties = labels, constants, properties
        self.reserved, self.jani, self.symbols = reserved, jani, symbols

    @property
    def program(self) -> Any:
        """Storm's program (or JANI model), parsed on first use for an own parse's file."""
        if self._program is None:
            assert self._storm is not None
            self._program = self._storm()
        return self._program

    @property
    def chain(self) -> bool:
        """Whether the file is a DTMC (one scheduler: ``P=?``, ``R=?`` and ``T=?`` need
        no ``min`` or ``max``, as Storm reads them)."""
        if self._program is None and self.symbols is not None:
            return bool(self.symbols.chain)
        return str(getattr(self.program, "model_type", "")).rsplit(".", 1)[-1] == "DTMC"


def read_program(path: str, constants: Mapping[str, Any] | None = None, *,
                 storm: bool = False) -> Program:
    """The PRISM file at ``path``, or the JANI file (``.jani``) with its properties.

    A PRISM file is read by our own parse (no stormpy) where it takes the file with the
    ``constants`` given (:func:`~mitld_lp.worlds.prism_symbols.read_own_program`;
    Storm's program is then parsed only if something asks for it), else, and always
    with ``storm``, by Storm, after the depth check that keeps Storm's parser from
    crashing (:mod:`mitld_lp.worlds.prism_depth`): a file Storm refuses is refused with
    Storm's words."""
    from pathlib import Path

    if Path(path).suffix.lower() == ".jani":
        from mitld_lp.worlds.jani import read_jani

        jani = read_jani(path)
        return Program(jani.model, jani.labels, jani.constants, tuple(jani.properties),
                       jani.variables, jani=True)
    from mitld_lp.worlds.prism_depth import ExpressionDepth, check_text

    check_text(Path(path), path, ExpressionDepth())
    if not storm:
        from mitld_lp.worlds.prism_symbols import read_own_program

        symbols = read_own_program(path, constants or {})
        if symbols is not None:
            return Program(None, dict(symbols.labels), frozenset(symbols.constants),
                           symbols=symbols, storm=lambda: storm_program(path))
    program = storm_program(path)
    return Program(program, {lab.name: str(lab.expression) for lab in program.labels},
                   frozenset(c.name for c in program.constants))


def storm_program(path: str) -> Any:
    """Storm's parse of the PRISM file at ``path`` (its depth checked already)."""
    from mitld_lp.worlds.prism import stormpy_module
    from mitld_lp.worlds.prism_program import parse_program

    return parse_program(stormpy_module(), path, path)


def _parse_error(message: str, text: str, where: str) -> PropertyError:
    """Storm's parse error as ``WHERE:LINE:COLUMN: ...``, the place found in ``text``
    from the excerpt Storm shows (its own position counts from the property's start)."""
    first = message.strip().splitlines()[0] if message.strip() else "cannot parse"
    first = re.sub(r"^\w*Exception: ", "", first)
    m = re.search(r"Parsing error at (\d+):(\d+):\s*(.*?)(?:, here:)?$", first)
    lines = message.splitlines()
    if m and "here:" in message:
        at = next((i for i, line in enumerate(lines) if line.rstrip().endswith("here:")), -1)
        excerpt = lines[at + 1].strip("\t") if 0 <= at < len(lines) - 1 else ""
        column = int(m[2])
        start = text.find(excerpt) if excerpt else -1
        if start >= 0:
            offset = start + column - 1
            line = text.count("\n", 0, offset) + 1
            col = offset - (text.rfind("\n", 0, offset) + 1) + 1
            near = text[offset:offset + 20].split("\n")[0]
            at_text = f"at {near!r}" if near.strip() else "at the end"
            return PropertyError(f"{where}:{line}:{col}: property parse error: {m[3].strip()}"
                                 f" {at_text}")
        return PropertyError(f"{where}:{m[1]}:{m[2]}: property parse error: {m[3].strip()}")
    return PropertyError(f"{where}: property error: {first}")


def read_properties(program: Any, text: str, where: str,
                    constants: Mapping[str, Any] | None = None) -> list[Any]:
    """Storm's properties of ``text`` (one property, or a properties file's text, with
    its ``const`` lines and ``"name":`` prefixes) for ``program``, the ``constants``
    the properties leave open put in (``program`` a Storm PRISM program or JANI model)."""
    from mitld_lp.worlds.prism import stormpy_module
    from mitld_lp.worlds.prism_program import storm_quiet

    stormpy = stormpy_module()

    errors = (RuntimeError, stormpy.exceptions.StormError)
    try:
        with storm_quiet():
            props = stormpy.parse_properties(text, program)
    except errors as exc:
        raise _parse_error(str(exc), text, where) from None
    if not props:
        raise PropertyError(f"{where}: no property in it")
    return instantiate(program, props, where, constants)


def instantiate(program: Any, props: list[Any], where: str,
                constants: Mapping[str, Any] | None = None) -> list[Any]:
    """Storm's ``props`` with the ``constants`` they leave open put in (every open one
    needs a value), and the file's open constants given among ``constants`` too (a
    bound ``F<=B`` or ``C<=B`` over the file's ``B`` is then a number)."""
    from mitld_lp.worlds.prism import stormpy_module
    from mitld_lp.worlds.prism_program import storm_quiet

    stormpy = stormpy_module()
    errors = (RuntimeError, stormpy.exceptions.StormError)
    open_names = sorted({v.name for p in props for v in p.get_undefined_constants()})
    declared = {c.name for c in program.constants if not c.defined}
    given = {k: v for k, v in (constants or {}).items() if k in open_names or k in declared}
    missing = [name for name in open_names if name not in given]
    if missing:
        raise PropertyError(f"{where}: constants {', '.join(missing)} have no value: give "
                            "them with --const NAME=VALUE")
    if given:
        try:
            with storm_quiet():
                props = stormpy.instantiate_constants(program, given, props)[1]
        except errors as exc:
            raise PropertyError(f"{where}: {str(exc).strip().splitlines()[0]}") from None
    return list(props)


def pick(props: list[Any], which: str | None, where: str) -> list[tuple[str, Any]]:
    """``(name, property)`` of every property (``which`` None), or of the one ``which``
    names: a name given as ``"name":``, or a number from 1 (PRISM's ``-prop``)."""
    named = [(p.get_name() if p.get_name() and not p.get_name().isdigit() else str(i),
              p) for i, p in enumerate(props, 1)]
    if which is None:
        return named
    if which.isdigit():
        k = int(which)
        if 1 <= k <= len(named):
            return [named[k - 1]]
        raise PropertyError(f"{where}: no property number {k} (it has {len(named)})")
    for name, p in named:
        if name == which:
            return [(name, p)]
    names = ", ".join(n for n, _ in named)
    raise PropertyError(f"{where}: no property named {which!r} (properties: {names})")


# --------------------------------------------------------------------------- posing


def refusal(name: str, text: str, form: str, why: str) -> PropertyError:
    return PropertyError(f"property {name} ({text}): {form} is refused: {why}")


class StatePoser:
    """The state formulas of one property made propositions (see the module); each
    formula is read from its printing as Storm prints it (Storm's formula, or our
    reader's printing of the same: :mod:`mitld_lp.worlds.property_own`)."""

    def __init__(self, name: str, text: str, labels: Mapping[str, str],
                 reserved: frozenset[str] = frozenset()) -> None:
        self.name, self.text, self.labels, self.reserved = name, text, labels, reserved
        self.define: dict[str, str] = {}

    def refuse(self, form: str, why: str) -> PropertyError:
        return refusal(self.name, self.text, form, why)

    def state(self, formula: Any) -> str:
        """A state formula (Storm's, or its printing) as a proposition of the task."""
        shown = str(formula).strip()
        bare = _LABEL.sub("", shown)
        if _NESTED.search(bare):
            raise self.refuse("a P, R, S or T operator inside a path formula",
                              "a nested operator is not a state of the world; the task "
                              "reads labels and expressions only")
        if _TEMPORAL.search(bare):
            raise self.refuse("a temporal operator nested in another (LTL)",
                              "only one of F, G, X, U over state formulas is taken (PCTL)")
        for label in _LABEL.findall(shown):
            if label in ("init", "deadlock"):
                raise self.refuse(f'Storm\'s label "{label}"',
                                  "it is not a label of the file; write the condition "
                                  "as an expression over the variables")
            if label not in self.labels:
                known = ", ".join(sorted(self.labels)) or "none"
                raise PropertyError(f"property {self.name} ({self.text}): label "
                                    f"{label!r} is not defined (labels: {known})")
        from mitld_lp.logic.syntax import is_proposition_name

        one = re.fullmatch(r'(!?)"(\w+)"', shown)
        if one and is_proposition_name(one[2]):
            return f"{one[1]}{one[2]}"
        if shown in ("true", "false"):
            return shown
        expression = _LABEL.sub(lambda m: f"({self.labels[m[1]]})", shown)
        taken = set(self.labels) | set(self.define) | self.reserved
        k = len(self.define) + 1
        while f"phi{k}" in taken or not is_proposition_name(f"phi{k}"):
            k += 1
        self.define[f"phi{k}"] = expression
        return f"phi{k}"

    def bound(self, formula: Any, left: Any) -> tuple[int, int]:
        """The steps ``[a, b]`` of a bounded until, from Storm's printing of it
        (``left U<=5 right``; stormpy gives neither the kind of bound nor its lower end)."""
        rest = str(formula)[len(str(left)):].lstrip()
        found = re.match(r"U(?:steps|rew\{[^}]*\})?(?:\[[^\]]*\]|\S*)", rest)
        op = found[0] if found else rest.split(" ")[0]
        op = re.sub(r"^Usteps", "U", op)  # a JANI file's step bound (``Usteps<=3``)
        numbers = r"([^,\]]+)"
        m = (re.fullmatch(r"U\s*(<=?)\s*(\S+)", op) or
             re.fullmatch(rf"U\s*\[\s*{numbers}\s*,\s*{numbers}\s*\]", op))
        if m is None:
            why = ("a reward bound is not a step bound" if "rew" in op or "{" in op else
                   "a bound with only a lower end leaves the steps unbounded"
                   if re.match(r"U\s*>", op) else f"the bound {op[1:]!r} is not one of "
                   "<=k, <k, [a,b]")
            raise self.refuse(f"the bound {op!r}", why)

        def integer(text: str) -> int:
            try:
                value = Fraction(text.strip())
            except ValueError:
                raise self.refuse(f"the bound {op!r}", f"{text.strip()!r} is not a "
                                  "number (a constant without a value?)") from None
            if value.denominator != 1 or value < 0:
                raise self.refuse(f"the bound {op!r}", "a step bound must be a "
                                  "non-negative integer (time-bounded operators count steps)")
            return int(value)

        if m[1] in ("<", "<="):
            b = integer(m[2]) - (m[1] == "<")
            if b < 0:
                raise self.refuse(f"the bound {op!r}", "no step is below 0")
            return 0, b
        a, b = integer(m[1]), integer(m[2])
        if a > b:
            raise self.refuse(f"the bound {op!r}", "the interval is empty")
        return a, b

    def path(self, formula: Any) -> str:
        import stormpy.logic as logic  # pyright: ignore[reportMissingImports]

        if isinstance(formula, logic.EventuallyFormula):
            return f"F {self.state(formula.subformula)}"
        if isinstance(formula, logic.GloballyFormula):
            return f"G {self.state(formula.subformula)}"
        if isinstance(formula, logic.BoundedUntilFormula):
            left, right = formula.left_subformula, formula.right_subformula
            a, b = self.bound(formula, left)
            lhs = self.state(left)
            target = self.state(right)
            return f"F[{a},{b}] {target}" if lhs == "true" else f"{lhs} U[{a},{b}] {target}"
        if isinstance(formula, logic.UntilFormula):
            return (f"{self.state(formula.left_subformula)} U "
                    f"{self.state(formula.right_subformula)}")
        shown = str(formula).strip()
        if isinstance(formula, logic.StateFormula):
            raise self.refuse("a state formula where a path formula belongs",
                              "the property asks nothing over time")
        if shown.startswith("X ") and type(formula).__name__ == "Formula":
            return f"X {self.state(shown[2:])}"  # stormpy binds no class for X
        raise self.refuse("a Boolean combination of path formulas (LTL)",
                          "only one of F, G, X, U over state formulas is taken (PCTL)")


def pose_property(name: str, prop: Any, labels: Mapping[str, str],
                  reserved: frozenset[str] = frozenset(), *, chain: bool = False) -> Query:
    """The task of Storm's property ``prop`` (``labels``: the file's ``name ->
    expression``; ``reserved``: names a new proposition must not take; ``chain``: the
    file is a DTMC, :attr:`Program.chain`), or :class:`PropertyError` naming the form
    refused and why."""
    own = getattr(prop, "pose", None)
    if own is not None:  # read by our reader (mitld_lp.worlds.property_own)
        return own(name, labels, reserved, chain=chain)
    import stormpy.logic as logic  # pyright: ignore[reportMissingImports]

    formula = prop.get_raw_formula()
    text = str(formula)
    if not INIT_FILTER.search(str(prop)):
        raise refusal(name, text, "a filter", "only the value at the initial state is "
                      "answered")
    kinds = ((logic.RewardOperatorFormula, "an expected reward (R)",
              "an expected reward is not the probability of a task (the door "
              "answers it: mitld_lp.worlds.prism_rewards)"),
             (logic.LongRunAverageOperatorFormula, "a long-run average (S)",
              "a long-run average is not a probability of a task"),
             (logic.TimeOperatorFormula, "an expected time (T)",
              "an expected time is not the probability of a task (the door answers it "
              "as an expected reward of 1 per step: mitld_lp.worlds.prism_rewards)"),
             (logic.MultiObjectiveFormula, "a multi-objective query",
              "one property poses one objective"))
    for kind, form, why in kinds:
        if isinstance(formula, kind):
            raise refusal(name, text, form, why)
    if not isinstance(formula, logic.ProbabilityOperatorFormula):
        raise refusal(name, text, "a state formula that is not one P operator",
                      "one P[...] per property is answered")
    objective, comparison, threshold = probability_objective(name, formula, chain=chain)
    poser = StatePoser(name, text, labels, reserved)
    spec = poser.path(formula.subformula)
    return Query(name=name, text=text, spec=spec, define=poser.define, objective=objective,
                 comparison=comparison, threshold=threshold)


def probability_objective(name: str, formula: Any, letter: str = "P",
                          what: str = "the probability", *, chain: bool = False,
                          ) -> tuple[str, str | None, Fraction | None]:
    """``(objective, comparison, threshold)`` of Storm's ``P`` operator ``formula``:
    ``Pmax=?`` is ``("max", None, None)``; ``P>=p`` asks for every scheduler, so the
    least probability decides it, ``("min", ">=", p)`` (``Pmax>=p``: the greatest).
    The same for an ``R`` or ``T`` operator (``letter``; ``what`` its quantity in the
    refusal), as Storm reads ``R<=b``: the greatest expected reward decides it.  On a
    DTMC (``chain``) ``P=?`` is its one value (``"max"``, which is also the least)."""
    comparison = threshold = None
    if formula.has_bound:
        comparison = _COMPARISONS[str(formula.comparison_type).rsplit(".", 1)[-1]]
        # the expression's value: Storm's ``threshold`` of ``P>1/2`` is 0 (integer typed)
        threshold = Fraction(str(formula.threshold_expr.evaluate_as_rational()))
    optimality = None
    if formula.has_optimality_type:
        optimality = "min" if "MIN" in str(formula.optimality_type).upper() else "max"
    return objective_of(name, str(formula), optimality, comparison, threshold, letter,
                        what, chain=chain)


def objective_of(name: str, text: str, optimality: str | None, comparison: str | None,
                 threshold: Fraction | None, letter: str = "P",
                 what: str = "the probability", *, chain: bool = False,
                 ) -> tuple[str, str | None, Fraction | None]:
    """``(objective, comparison, threshold)`` of an operator printed ``text`` with the
    ``optimality`` (``"min"``, ``"max"`` or None) and bound it was written with (see
    :func:`probability_objective`)."""
    if optimality is not None:
        objective = optimality
    elif comparison is not None:  # for every scheduler: the worst one decides
        objective = "min" if comparison in (">=", ">") else "max"
    elif chain:  # one scheduler: its value is the greatest and the least
        objective = "max"
    else:
        raise refusal(name, text, f"{letter}=? without min or max",
                      f"on an MDP {what} depends on the scheduler: write {letter}max=? "
                      f"or {letter}min=?")
    return objective, comparison, threshold


def verdict(query: Any, lower: Fraction | float, upper: Fraction | float) -> bool | None:
    """``P~p`` (or ``R~b``, ``T~b``: any ``query`` with a ``comparison`` and a
    ``threshold``) decided by the optimum's bracket ``[lower, upper]`` (exact rationals,
    or ``math.inf`` both for an infinite expected reward): True or False when the whole
    bracket is on one side of the threshold, None (undecided) when it straddles it."""
    p, op = query.threshold, query.comparison
    if p is None or op is None:
        raise ValueError("not a P~p property")
    holds = {">=": lambda v: v >= p, ">": lambda v: v > p, "<=": lambda v: v <= p,
             "<": lambda v: v < p}[op]
    if holds(lower) and holds(upper):
        return True
    if not holds(lower) and not holds(upper):
        return False
    return None

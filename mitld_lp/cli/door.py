"""``solve`` on a PRISM file, as Storm's users type it: ``mitld-lp solve FILE.prism --prop
'Pmax=? [F "goal"]' --const N=20,K=2``.

``--prop`` is a property or a properties file (``.props``, ``.prctl``, ``.pctl``: every
property of it, one line or one JSON object each, or the one a name or a number from 1
picks), read by our reader (:mod:`mitld_lp.worlds.property_own`) or, for the forms it
leaves to Storm, by Storm's; each is posed as a task by
:mod:`mitld_lp.worlds.properties` (the forms it refuses are refused by name, exit 2)
and answered with the certified bracket; ``P~p`` is answered true or false by the
bracket, or undecided when the bracket straddles ``p`` (exit 3).  ``--spec`` poses an
MITLD task over the same file instead, answered as a model file's (:func:`world_model`).
``--objective`` sets a model file's objective too (:mod:`mitld_lp.cli.solve` passes it
to :func:`mitld_lp.synthesis.pose`).
"""

from __future__ import annotations

import argparse
import re
import time
from fractions import Fraction
from pathlib import Path
from typing import Any

from mitld_lp.cli.kernel import (
    EXIT_OK,
    EXIT_UNCERTIFIED,
    EXIT_USAGE,
    UsageError,
    error_record,
    is_pattern,
    json_text,
    model_options,
    probability_head,
    say_answer,
    write_file,
)
from mitld_lp.files import write as files
from mitld_lp.model import ModelError
from mitld_lp.report import bracket_text

__all__ = ["WORLD_SUFFIXES", "args_door", "is_world_file", "check_args", "world_model",
           "solve_properties"]

#: The files ``solve`` reads as a world with a property, not as a model file.
WORLD_SUFFIXES = (".prism", ".pm", ".nm", ".jani")
PROPERTY_SUFFIXES = (".props", ".prctl", ".pctl", ".prop")


def args_door(p: argparse.ArgumentParser) -> None:
    p.add_argument("--prop", nargs="+", metavar="PROP",
                   help="with a PRISM file: a property ('Pmax=? [F \"goal\"]') or a "
                        "properties file, optionally with the name or number (from 1) of "
                        "the one to answer (default: every one)")
    p.add_argument("--const", metavar="N=V,...", default="",
                   help="with a PRISM file: values of its open constants (and the "
                        "properties'), N=20,K=2,p=0.1,b=true")
    p.add_argument("--spec", metavar="FORMULA",
                   help="with a PRISM file: an MITLD task over its labels instead of --prop")
    p.add_argument("--objective", choices=("max", "min", "min-steps", "min-cost"),
                   help="maximise or minimise the probability of the task (default: the "
                        "model file's, max; with --prop the property says), or minimise "
                        "the expected steps (cost) of satisfying it")


def is_world_file(path: str) -> bool:
    return Path(path).suffix.lower() in WORLD_SUFFIXES


def check_args(args: argparse.Namespace) -> bool:
    """Whether ``solve`` reads a PRISM file; refuses, at the start, the options a model
    file does not take and the ones a PRISM file's property does not."""
    files = args.model
    worlds = [f for f in files if is_world_file(f)]
    if worlds and len(files) > 1:
        raise UsageError(f"solve: {worlds[0]}: a PRISM or JANI file is solved alone, not "
                         "in a batch of model files")
    if not worlds:
        if args.objective and (len(files) > 1 or is_pattern(files[0])):
            raise UsageError("solve: --objective goes with one model file, not a batch "
                             "(each file says its objective)")
        for flag, given in (("--prop", args.prop), ("--const", args.const),
                            ("--spec", args.spec)):
            if given:
                raise UsageError(f"solve: {flag} goes with a PRISM file; a model file "
                                 "holds its own task and constants")
        return False
    jani = Path(worlds[0]).suffix.lower() == ".jani"
    if args.prop is not None and args.spec is not None or (
            args.prop is None and args.spec is None and not jani):
        raise UsageError(f"solve: {worlds[0]}: give a property with --prop (or an MITLD "
                         "task with --spec), one of the two")
    if args.spec is None:
        if args.prop is not None and len(args.prop) > 2:
            raise UsageError("--prop takes a property, or a properties file and the name "
                             "or number of one of its properties")
        for flag, given in (("--constraint", args.constraint), ("--then", args.then),
                            ("--objective", args.objective)):
            if given:
                raise UsageError(f"solve: {flag} does not go with --prop: the property is "
                                 "the whole question (use --spec for a task with "
                                 f"{flag})")
    return True


def _world(args: argparse.Namespace, constants: dict[str, Any], define: dict[str, str],
           task: Any) -> Any:
    """The PRISM world for one task, under the command's world budgets; its faults as
    the model's (exit 2; a budget stop stays one)."""
    from mitld_lp.worlds import WorldError
    from mitld_lp.worlds.jani import load_jani
    from mitld_lp.worlds.prism import PrismTooLarge, load_prism

    kwargs: dict[str, Any] = {}
    if args.max_world_states is not None:
        kwargs["max_states"] = args.max_world_states
    load = load_jani if Path(args.model).suffix.lower() == ".jani" else load_prism
    if load is load_prism and getattr(args, "exact", False):
        kwargs["explore"] = "full"  # the exact answer reads the whole world
    try:
        return load(args.model, constants=constants, define=define, task=task,
                    max_memory=args.max_memory, **kwargs)
    except PrismTooLarge:
        raise
    except WorldError as exc:  # the loader's keyword is --const here
        raise ModelError(str(exc).replace("constants={...}", "--const NAME=VALUE")) from exc


def _constants(args: argparse.Namespace) -> dict[str, Any]:
    from mitld_lp.worlds.properties import PropertyError, parse_constants

    try:
        return parse_constants(args.const)
    except PropertyError as exc:
        raise UsageError(str(exc)) from None


def world_model(args: argparse.Namespace) -> Any:
    """``--spec``'s task over the PRISM file as a model, answered as a model file's."""
    from mitld_lp.logic.parser import ParseError, parse
    from mitld_lp.model import Model

    try:
        task = parse(args.spec)
    except ParseError as exc:
        raise ModelError(f"--spec: {exc.line}:{exc.column}: {exc.reason}") from exc
    game = _world(args, _constants(args), {}, task)
    return Model.from_game(game, args.spec, name=Path(args.model).stem,
                           objective=args.objective or "max")


def _declared(args: argparse.Namespace, constants: dict[str, Any], program: Any,
              theirs: set[str]) -> None:
    """Refuse a ``--const`` name that neither the file nor its properties (``theirs``)
    declare: a typo is named, never dropped."""
    stray = sorted(k for k in constants if k not in program.constants and k not in theirs)
    if stray:
        raise ModelError(f"{args.model}: constant {stray[0]!r} is not declared (constants: "
                         f"{', '.join(sorted(program.constants))})")


def _properties(args: argparse.Namespace, constants: dict[str, Any]) -> tuple[list[Any],
                                                                              Any]:
    """``(name, property)`` of each property posed, and the PRISM or JANI file read (a
    PRISM file by our own parse where it takes the file with the constants given, so
    that a property our reader reads imports no stormpy; a JANI file's own properties:
    every one without ``--prop``, or the one ``--prop NAME`` or ``--prop NUMBER``
    names)."""
    from mitld_lp.files import rules
    from mitld_lp.worlds import WorldError
    from mitld_lp.worlds.properties import instantiate, pick, read_program
    from mitld_lp.worlds.property_own import read_any

    try:
        program = read_program(args.model, constants)
        own = list(program.properties)
        if own and (args.prop is None or len(args.prop) == 1 and (
                args.prop[0].isdigit() or any(p.get_name() == args.prop[0] for p in own))):
            which = None if args.prop is None else args.prop[0]
            _declared(args, constants, program, {
                c.name for p in own for c in p.get_undefined_constants()})
            props = instantiate(program.program, own, args.model, constants)
            return pick(props, which, args.model), program
    except WorldError as exc:
        raise ModelError(str(exc)) from exc
    if args.prop is None:
        raise UsageError(f"solve: {args.model}: the file has no property: give one with "
                         "--prop (or an MITLD task with --spec)")
    given, *which = args.prop
    path = Path(given)
    if path.suffix.lower() in PROPERTY_SUFFIXES or path.is_file():
        try:
            text = rules.read_bytes(path, rules.read_limit(args.max_memory)).decode("utf-8")
        except (OSError, rules.InputFileError, UnicodeDecodeError) as exc:
            raise UsageError(f"--prop: {given}: cannot read: "
                             f"{getattr(exc, 'strerror', None) or exc}") from None
        where = given
    elif which:
        raise UsageError(f"--prop: {given!r} is a property, not a properties file: no "
                         "property to pick from it")
    else:
        text, where = given, "--prop"
    _declared(args, constants, program, {k for k in constants
                                         if re.search(rf"\b{re.escape(k)}\b", text)})
    try:
        props = read_any(program, text, where, constants)  # ours, or Storm's reader
        return pick(props, which[0] if which else None, where), program
    except WorldError as exc:
        raise ModelError(str(exc)) from exc


def solve_properties(args: argparse.Namespace, policy_file: Path | None = None) -> int:
    """Every property posed answered, one line (one JSON object) each; the exit code
    the worst of theirs (2 when one was refused, 3 when one is not certified or
    undecided)."""
    from mitld_lp.cli.bounded import answer_reward_bounded
    from mitld_lp.cli.rewards import answer_reward
    from mitld_lp.logic.parser import parse
    from mitld_lp.model import Model
    from mitld_lp.problem import settings_from
    from mitld_lp.synthesis import pose, solve
    from mitld_lp.worlds.prism_rewards import is_reward
    from mitld_lp.worlds.properties import PropertyError, pose_property
    from mitld_lp.worlds.property_own import OwnProperty
    from mitld_lp.worlds.reward_bounded import is_reward_bounded

    constants = _constants(args)
    props, program = _properties(args, constants)
    ours = {k: v for k, v in constants.items() if k in program.constants}
    if policy_file is not None and len(props) > 1:
        raise UsageError(f"--policy: {len(props)} properties posed, one policy file: pick "
                         "one property (--prop FILE NAME)")
    codes = []
    for name, prop in props:
        started = time.perf_counter()
        storm = not isinstance(prop, OwnProperty)  # ours reads no R, T, reward bound
        try:
            if storm and is_reward(prop):  # an expected reward: its own exact solve
                if policy_file is not None:
                    raise UsageError("--policy: an expected reward (R) writes no policy "
                                     "file")
                codes.append(answer_reward(args, name, prop, program, ours))
                continue
            if storm and is_reward_bounded(prop):  # P over F{"r"}<=b: the reward unfolded
                if policy_file is not None:
                    raise UsageError("--policy: a reward-bounded probability writes no "
                                     "policy file")
                codes.append(answer_reward_bounded(args, name, prop, program, ours))
                continue
            query = pose_property(name, prop, program.labels, program.reserved,
                                  chain=program.chain)
            game = _world(args, ours, query.define, parse(query.spec))
            model = Model.from_game(game, query.spec, name=Path(args.model).stem,
                                    objective=query.objective)
        except (PropertyError, ModelError) as exc:
            if len(props) == 1:
                raise ModelError(str(exc)) from exc
            codes.append(EXIT_USAGE)
            record = error_record("model_error", str(exc), property=name)
            say_answer(json_text(record) if args.json else f"{name}: refused: {exc}")
            continue
        settings = settings_from(method=args.method, solver=args.solver,
                                 backend=args.backend, exact=args.exact,
                                 decompose=False if args.no_decompose else None,
                                 **model_options(args))
        r = solve(pose(model, settings=settings))
        if policy_file is not None:
            write_file(policy_file, lambda p, r=r: files.write_policy(r, p, overwrite=True))
        codes.append(_answer(args, query, model, r, time.perf_counter() - started))
    return max(codes, default=EXIT_OK)


def _answer(args: argparse.Namespace, query: Any, model: Any, r: Any, seconds: float) -> int:
    """One property's line (or JSON object); its exit code."""
    from mitld_lp.worlds.properties import verdict

    exact = getattr(r.exact, "value", None) if r.exact is not None else None
    lower, upper = ((exact, exact) if exact is not None else
                    (Fraction(r.lower), Fraction(r.upper)))
    decided = None if query.comparison is None else verdict(query, lower, upper)
    code = EXIT_OK if r.certified else EXIT_UNCERTIFIED
    if query.comparison is not None and decided is None:
        code = EXIT_UNCERTIFIED
    if args.json:
        record = {"property": query.name, "formula": query.text, "spec": query.spec,
                  "labels": query.define, **r.summary(), "seconds": seconds}
        if query.comparison is not None:
            record.update(comparison=query.comparison, threshold=str(query.threshold),
                          verdict=decided)
        say_answer(json_text(record))
        return code
    head = probability_head(query, bracket_text(r.lower, r.upper), decided)
    tail = [f"task {query.spec}" + "".join(f", {k} = {v}" for k, v in query.define.items()),
            "certified" if r.certified else f"NOT certified ({r.status.value})",
            f"{model.game.explored} world states, " + (
                f"{r.mdp.n_states} product states" if getattr(r.mdp, "product", True)
                else "no product (solved over the world)"),
            f"{seconds:.2f} s"]
    if exact is not None:
        tail.insert(1, f"exact {exact}")
    say_answer(f"{query.name}: {query.text}  {head}  ({'; '.join(tail)})")
    return code

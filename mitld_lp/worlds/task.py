"""The binding of a task to a world: which propositions a specification may use, which
events exist and which law each event has.

Every route to a model (a model file, :meth:`mitld_lp.Model.from_game`) calls
:func:`bind`, and :func:`mitld_lp.product.product` calls :func:`check_alphabet`, the
half of it that needs no formula; nothing else repeats these rules:

* **laws** (:func:`resolve_laws`): each event of the spec gets the law its ``D[mu]``
  names, ``D[name]`` looked up in the named laws, an inline literal such as
  ``D[geometric(0.3)]`` built once; a named law the spec does not use is an error
  (nothing given is silently ignored).  That an event has one ``D[mu]`` only is the
  fragment's rule (:func:`mitld_lp.logic.fragment.check`), which the report carries.
* **alphabet** (:func:`check_alphabet`): no proposition of the world has an event's
  name; every other proposition the spec reads is a proposition of the world (else it
  could never be true, and the answer would be a silent 0); every event the world
  reacts to has a law (else it would silently never happen).

Errors are :class:`BindError` (a ``ValueError``) whose ``key`` says where the fault is,
so that a model file can name its key path and a library call its argument.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from mitld_lp.distributions import DistributionError, FirstOccurrence, from_spec
from mitld_lp.logic.fragment import FragmentReport
from mitld_lp.logic.syntax import DistLiteral, DistRef, Formula, atoms, is_proposition_name
from mitld_lp.util.text import printable
from mitld_lp.worlds.game import Game, WorldMembers, world_members

__all__ = ["BindError", "Task", "bind", "resolve_laws", "check_alphabet"]


class BindError(ValueError):
    """A task that does not fit its world, or laws that do not fit the task.

    ``key`` is where the fault is: ``("spec",)``; ``("distributions", name)`` for a named
    law; ``("proposition", name)`` for a proposition of the world.  ``reason`` says what
    is wrong; ``str(error)`` is the reason, one printable line."""

    def __init__(self, key: tuple[str, ...], reason: str) -> None:
        self.key = key
        self.reason = printable(reason)
        super().__init__(self.reason)

    def __reduce__(self) -> tuple[Any, ...]:
        return (BindError, (self.key, self.reason))


@dataclass(frozen=True, slots=True)
class Task:
    """A specification bound to a world.

    Attributes:
        world: the game.
        formula: the specification.
        laws: read-only mapping ``event -> law``, one entry per external event of the
            spec (the events are exactly its keys).
    """

    world: Game[Any]
    formula: Formula
    laws: Mapping[str, FirstOccurrence]

    @property
    def events(self) -> frozenset[str]:
        """The external events of the specification."""
        return frozenset(self.laws)


def resolve_laws(
    report: FragmentReport, named: Mapping[str, FirstOccurrence] | None = None
) -> dict[str, FirstOccurrence]:
    """The law of each event of ``report``: ``D[name]`` looked up in ``named``, an inline
    literal built.  Raises :class:`BindError` for a named value that is no law, a name
    ``named`` does not bind, or a name it binds that the spec does not use."""
    given = dict(named or {})
    for name, law in given.items():
        if not isinstance(law, FirstOccurrence):
            raise BindError(
                ("distributions", str(name)),
                f"must be a distribution (mitld_lp.distributions), got "
                f"{type(law).__name__} {law!r}",
            )
    laws: dict[str, FirstOccurrence] = {}
    used: set[str] = set()
    for event, mu in report.events:
        if isinstance(mu, DistRef):
            if mu.name not in given:
                known = ", ".join(sorted(given)) or "none"
                raise BindError(
                    ("spec",),
                    f"distribution {mu.name!r} (of event {event!r}) is not defined under "
                    f"[distributions] (defined: {known})",
                )
            used.add(mu.name)
            laws[event] = given[mu.name]
        elif isinstance(mu, DistLiteral):
            try:
                laws[event] = from_spec(mu)
            except DistributionError as exc:
                raise BindError(("spec",), f"D[{mu}] {event}: {exc.reason}") from exc
        else:  # pragma: no cover - a DistSpec is a name or a literal
            raise TypeError(f"event {event!r}: not a distribution: {mu!r}")
    for name in given:
        if name not in used:
            raise BindError(
                ("distributions", name), f"defined but not used by spec (it has no D[{name}])"
            )
    return laws


def check_alphabet(
    world: Game[Any],
    propositions: Iterable[str],
    events: Iterable[str],
    *,
    noun: str = "proposition",
) -> WorldMembers:
    """Check that a task reading ``propositions`` (events included) with laws for
    ``events`` fits ``world`` (see the module docstring), and return the world's
    declared members.  ``noun`` is what the world calls its propositions in messages (a
    grid's are regions, a PRISM file's labels).  Raises :class:`BindError`, or
    :class:`mitld_lp.worlds.game.GameError` when the world's members are missing or wrong
    (:func:`mitld_lp.worlds.game.world_members`)."""
    members = world_members(world)
    events = frozenset(events)
    props = frozenset(world.proposition_names)
    clashes = sorted(events & props)
    if clashes:
        raise BindError(
            ("proposition", clashes[0]),
            f"{noun} {clashes[0]!r} has the name of an event of spec (an event is not a {noun})",
        )
    unknown = sorted(frozenset(propositions) - events - props)
    if unknown:
        known = ", ".join(sorted(props)) or "none"
        evs = ", ".join(sorted(events)) or "none"
        raise BindError(
            ("spec",),
            f"proposition {unknown[0]!r} is neither a {noun} nor an event "
            f"({noun}s: {known}; events: {evs})",
        )
    lawless = sorted(members.event_names - events)
    if lawless:
        raise BindError(
            ("spec",),
            f"the game reacts to event {lawless[0]!r} but the spec gives it no distribution "
            f"(add D[mu] {lawless[0]} to the spec)",
        )
    return members


def bind(
    world: Game[Any],
    report: FragmentReport,
    named: Mapping[str, FirstOccurrence] | None = None,
    *,
    noun: str = "proposition",
    declared: Mapping[str, FirstOccurrence] | None = None,
) -> Task:
    """The task of ``report``'s formula on ``world``: each event's law
    (:func:`resolve_laws`), checked against the world (:func:`check_alphabet`).

    ``declared``: events of the world given their laws without the spec asking that
    they happen (a model file's ``[events]``); the spec may read them as propositions.
    An event gets its law in one place: there or from a ``D[mu]`` of the spec.
    Raises :class:`BindError`."""
    laws = resolve_laws(report, named)
    for event, law in (declared or {}).items():
        where = ("events", str(event))
        if not isinstance(law, FirstOccurrence):
            raise BindError(where, f"must be a distribution (mitld_lp.distributions), got "
                                   f"{type(law).__name__} {law!r}")
        if not is_proposition_name(event):
            raise BindError(where, f"{event!r} is not a name a formula can read (letters, "
                                   "digits, _; not a reserved word)")
        if event in laws:
            raise BindError(where, f"event {event!r} also gets a law from the spec's D[...] "
                                   f"{event}; give it one law, in one place")
        if event in world.proposition_names:
            raise BindError(where, f"event {event!r} has the name of a {noun} of the world")
        laws[event] = law
    check_alphabet(world, atoms(report.formula), laws, noun=noun)
    return Task(world, report.formula, MappingProxyType(laws))

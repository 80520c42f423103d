"""Sensors: how the robot learns that an external event happened.

An event ``a`` with a sensor ``Sensor(detect=d, delay=D)`` happens at its hidden step
``K`` (its law); from step ``K + D`` on, each step the sensor reports it with
probability ``d``, independently of everything else, until it has reported it once.
``d = 1, D = 0`` is the fully observed semantics (the robot sees the event the step it
happens); an event without a sensor is seen that way.

With ``false_alarm = f > 0`` the sensor reports or not at *every* step, independently:
with probability ``f`` before step ``K + D`` and ``d`` from it on (a report no longer
means the event happened, and every report counts, not only the first).  With a law
that surely happens the information-state product builds it
(:mod:`mitld_lp.sensing.belief`), constraints and ``then`` too; with a law that may
never happen the ``sensed`` route brackets the optimum (:mod:`mitld_lp.routes.sensed_never`),
but on a world whose moves react to the event (:mod:`mitld_lp.sensing.reacting`, which
builds the laws that surely happen) it is refused;
a law known within a band is solved where its laws surely happen (its worst case without
constraints, its best law with or without them); a band read for its worst law with
constraints, and a law that may never happen with constraints, are refused by name
(:func:`mitld_lp.routes.sensed.false_alarm_refusal` says why).

A model file writes them under ``[sensors]``::

    [sensors]
    b1 = { detect = 0.8 }
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from mitld_lp.files.keys import KeyContext, key_path, toml_text, type_name

__all__ = ["Sensor", "read_sensors", "sensors_from", "partial", "SENSOR_KEYS",
           "reacting_events"]

SENSOR_KEYS = ("detect", "false_alarm", "delay")


@dataclass(frozen=True, slots=True)
class Sensor:
    """How one event is reported (module docs): ``detect`` the per-step probability of a
    report once the event has happened, ``false_alarm`` the per-step probability of a
    report before it, ``delay`` the steps after the event before its report can come."""

    detect: float
    false_alarm: float = 0.0
    delay: int = 0

    @property
    def perfect(self) -> bool:
        """The fully observed semantics: reported the step the event happens."""
        return self.detect == 1.0 and self.false_alarm == 0.0 and self.delay == 0

    def __str__(self) -> str:
        extra = "".join(
            f", {k} = {toml_text(getattr(self, k))}" for k in ("false_alarm", "delay")
            if getattr(self, k))
        return f"{{ detect = {toml_text(self.detect)}{extra} }}"


def _probability(ctx: KeyContext, value: Any, path: str, *, one: bool) -> float:
    v = ctx.number(value, path)
    if not (0.0 <= v <= 1.0) or (not one and v == 1.0):
        what = "[0, 1]" if one else "[0, 1)"
        raise ctx.error(path, f"must be a probability in {what}, got {toml_text(value)}")
    return v


def _one(ctx: KeyContext, value: Any, path: str) -> Sensor:
    if isinstance(value, Sensor):
        value = {k: getattr(value, k) for k in SENSOR_KEYS}
    if not isinstance(value, Mapping):
        raise ctx.error(path, f"must be a table such as {{ detect = 0.8 }}, got "
                              f"{type_name(value)} {toml_text(value)}")
    table = dict(value)
    ctx.keys(table, path, {"detect"}, {"false_alarm", "delay"})
    detect = _probability(ctx, table["detect"], key_path(path, "detect"), one=True)
    false_alarm = 0.0
    if "false_alarm" in table:
        false_alarm = _probability(ctx, table["false_alarm"], key_path(path, "false_alarm"),
                                   one=False)
    delay = 0
    if "delay" in table:
        delay = ctx.integer(table["delay"], key_path(path, "delay"))
        if delay < 0:
            raise ctx.error(key_path(path, "delay"), f"must be an integer >= 0, got {delay}")
    return Sensor(detect, false_alarm, delay)


def read_sensors(table: Any, events: Iterable[str], ctx: KeyContext,
                 path: str = "sensors") -> Mapping[str, Sensor]:
    """The ``[sensors]`` table of a model file (or :meth:`Model.from_game`'s
    ``sensors``): one :class:`Sensor` per event named, each event one of ``events``.
    Raises :class:`~mitld_lp.files.keys.ModelError` naming the key path
    (``sensors.b1.detect``)."""
    if not isinstance(table, Mapping):
        raise ctx.error(path, f"must be a table of events, got {type_name(table)} "
                              f"{toml_text(table)}")
    known = sorted(events)
    out: dict[str, Sensor] = {}
    for name, value in table.items():
        where = key_path(path, str(name))
        if name not in known:
            raise ctx.error(where, "not an event of the model (events: "
                                   f"{', '.join(known) or 'none'})")
        out[name] = _one(ctx, value, where)
    return MappingProxyType(dict(sorted(out.items())))


def sensors_from(value: Mapping[str, Any] | None, events: Iterable[str],
                 ctx: KeyContext) -> Mapping[str, Sensor]:
    """:func:`read_sensors` of an optional argument (``None``: no sensor)."""
    if value is None:
        return MappingProxyType({})
    return read_sensors(value, events, ctx)


def partial(sensors: Mapping[str, Sensor]) -> dict[str, Sensor]:
    """The sensors that change the problem: every one but the perfect ones
    (``detect = 1``, no false alarm, no delay), which are the fully observed semantics."""
    return {a: s for a, s in sensors.items() if not s.perfect}


def reacting_events(game: Any, sensed: Iterable[str]) -> frozenset[str]:
    """The events of ``sensed`` (names) that the world's moves react to (its
    ``event_names``): their sensors are built on the reacting product
    (:mod:`mitld_lp.sensing.reacting`); empty for a world whose members do not check
    (its loader reports that).  Here, not there, so that asking costs a route nothing."""
    from mitld_lp.worlds.game import GameError, world_members

    try:
        names = world_members(game).event_names
    except GameError:
        return frozenset()
    return frozenset(names) & frozenset(sensed)

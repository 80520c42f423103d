"""How a controller's decision tree (:mod:`mitld_lp.running.tree`) is held and written:
its nodes, the tree, and its three formats -- JSON (``{"format", "features", "nodes",
...}``, a node either ``{"id", "feature", "op", "value", "yes", "no"}`` or a leaf), Graphviz
DOT and a plain Python function.  A leaf holds the controller's decision: an action (or
``null`` where the task is lost), or for a randomised controller its distribution (the
actions with their probabilities, *stay* and, for a task with a safety part, *keep* with
the actions a run that drew it plays for ever).
"""

from __future__ import annotations

import json
import keyword
from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from mitld_lp.controllers.stepper import Decision

__all__ = ["Node", "Tree", "Memory", "FORMAT", "holds", "plain", "identifier", "fresh_name",
           "decision_label", "label_decision"]

FORMAT = "mitld_lp.running.tree"


@dataclass(frozen=True, slots=True)
class Node:
    """An inner node tests ``feature op value`` (``<=`` or ``==``) and goes to ``yes``
    or ``no``; a leaf (``feature`` None) holds ``decision``."""

    feature: int | None = None
    op: str = ""
    value: Any = None
    yes: int = -1
    no: int = -1
    decision: Any = None


@dataclass(frozen=True, slots=True)
class Memory:
    """The memory of a finite-memory controller whose tree reads it (a controller that
    acts on sensor reports: the memory is its information state, what the robot has
    observed): its ``initial`` value and its update, ``moves`` rows ``(memory, action,
    world values, events seen, reports, next memory)`` -- after the robot took ``action``
    in ``memory`` and observed the world in the state of those values, the events
    without a sensor that happened and the sensors' reports, the memory is ``next``
    (a number, or an end: ``"target"`` every hypothesis left accepted the task,
    ``"sink"`` every one rejected it, ``"truncated"`` decided, the robot cannot tell
    which); an observation no row lists has probability 0 in the model."""

    initial: int | str
    moves: tuple[tuple[Any, str, tuple[Any, ...], tuple[str, ...], tuple[str, ...], Any], ...]


@dataclass(frozen=True, slots=True)
class Tree:
    """The tree: ``features`` named, ``nodes[0]`` the root; ``samples`` the reachable
    states it was grown on (and is exact on)."""

    features: tuple[str, ...]
    events: tuple[str, ...]
    nodes: tuple[Node, ...]
    randomised: bool
    samples: int
    same_actions: bool = True
    automaton: tuple[str, ...] = ()  # per automaton state q, what it stands for
    memory: Memory | None = None  # a finite-memory controller's memory (its last feature)

    @property
    def size(self) -> int:
        """Its number of nodes (inner nodes and leaves)."""
        return len(self.nodes)

    @property
    def leaves(self) -> int:
        return sum(n.feature is None for n in self.nodes)

    def decide(self, values: Sequence[Any]) -> Any:
        """The leaf's decision for the feature ``values``."""
        node = self.nodes[0]
        while node.feature is not None:
            node = self.nodes[node.yes if holds(node, values[node.feature]) else node.no]
        return node.decision

    # ------------------------------------------------------------------ formats

    def to_json(self) -> str:
        nodes = []
        for i, n in enumerate(self.nodes):
            if n.feature is None:
                nodes.append({"id": i, **_leaf_json(n.decision, self.randomised)})
            else:
                nodes.append({"id": i, "feature": self.features[n.feature], "op": n.op,
                              "value": plain(n.value), "yes": n.yes, "no": n.no})
        out: dict[str, Any] = {
            "format": FORMAT, "version": 1, "features": list(self.features),
            "events": list(self.events), "randomised": self.randomised,
            "states": self.samples, "same_actions": self.same_actions,
            "automaton_states": {str(q): text for q, text in enumerate(self.automaton)},
            "nodes": nodes}
        if self.memory is not None:
            out["memory"] = {"initial": self.memory.initial, "moves": [
                {"memory": m, "action": a, "world": [plain(v) for v in w],
                 "events": list(e), "reports": list(r), "next": nxt}
                for m, a, w, e, r, nxt in self.memory.moves]}
        return json.dumps(out, indent=1) + "\n"

    def to_dot(self) -> str:
        lines = ["digraph tree {", '  node [fontname="Helvetica"];']
        if self.memory is not None:  # the picture is the decisions; the memory's table
            lines.insert(1, "  // a finite-memory controller: the memory's update "
                         "(INITIAL, MOVES) is in the .json and .py forms")
        for i, n in enumerate(self.nodes):
            if n.feature is None:
                text = _leaf_text(n.decision, self.randomised)
                lines.append(f'  n{i} [shape=box, label={json.dumps(text)}];')
            else:
                value = plain(n.value)
                shown = ("{" + ", ".join(map(str, value)) + "}" if n.op == "in" else
                         str(value).lower() if isinstance(value, bool) else value)
                test = f"{self.features[n.feature]} {n.op} {shown}"
                lines.append(f"  n{i} [shape=ellipse, label={json.dumps(test)}];")
                lines.append(f'  n{i} -> n{n.yes} [label="yes"];')
                lines.append(f'  n{i} -> n{n.no} [label="no", style=dashed];')
        lines.append("}")
        return "\n".join(lines) + "\n"

    def to_python(self) -> str:
        taken: set[str] = set()  # distinct Python names, whatever the features' names
        names = [identifier(fresh_name(f, taken)) for f in self.features]
        what = ("a dict {action: probability} (key None: stay in the end component; a key "
                "('keep', *actions): keep the safety part, playing those actions uniformly "
                "for ever)" if self.randomised else "the action (None: the task is lost, stop)")
        if self.memory is not None:
            return self._memory_python(names, what)
        world = len(self.features) - len(self.events) - 2
        out = ['"""The controller as a decision tree, written by mitld_lp (exact on the',
               f"{self.samples} states it can reach).  act(...) returns {what}.",
               f"Arguments: the world's {', '.join(names[:world])}; the controller's "
               f"{', '.join(names[world:])} (automaton state, pending events, clock).\"\"\"",
               "", "", f"def act({', '.join(names)}):"]
        self._emit(out, names)
        return "\n".join(out) + "\n"

    def _memory_python(self, names: list[str], what: str) -> str:
        """A finite-memory controller: ``act`` (the tree, on the world's variables and
        the memory), ``INITIAL`` and ``update`` (the memory's table)."""
        assert self.memory is not None
        world, mem = names[:-1], names[-1]
        taken = set(names)
        act, seen, told = (identifier(fresh_name(x, taken))
                           for x in ("action", "events", "reports"))
        moves = {(m, a, tuple(plain(v) for v in w), tuple(e), tuple(r)): nxt
                 for m, a, w, e, r, nxt in self.memory.moves}
        out = ['"""The controller as a finite-memory controller, written by mitld_lp: its',
               "memory is what the robot has observed (an information state), act(...) is a",
               f"decision tree exact on the {self.samples} (world state, memory) pairs it can",
               f"reach and returns {what}.",
               "Start with memory = INITIAL; after each step, memory = update(memory, the",
               "action taken, the new world state's "
               f"{', '.join(world)}, the events without a sensor that",
               "happened, the sensors' reports) (event names, sorted); an end (a string)",
               "or BEYOND (an observation the model gives probability 0) stays.\"\"\"",
               "", f"INITIAL = {self.memory.initial!r}", 'BEYOND = "beyond"',
               f"MOVES = {moves!r}", "", "",
               f"def update({mem}, {act}, {', '.join(world)}, {seen}, {told}):",
               f"    if isinstance({mem}, str):",
               f"        return {mem}",
               f"    key = ({mem}, {act}, ({', '.join(world)},), "
               f"tuple(sorted({seen})), tuple(sorted({told})))",
               "    return MOVES.get(key, BEYOND)", "", "",
               f"def act({', '.join(names)}):",
               f"    if isinstance({mem}, str):",
               "        return None"]
        self._emit(out, names)
        return "\n".join(out) + "\n"

    def _emit(self, out: list[str], names: list[str]) -> None:

        def emit(i: int, depth: int) -> None:
            n, pad = self.nodes[i], "    " * depth
            if n.feature is None:
                out.append(f"{pad}return {_leaf_python(n.decision, self.randomised)}")
                return
            out.append(f"{pad}if {_python_test(names[n.feature], n)}:")
            emit(n.yes, depth + 1)
            out.append(f"{pad}else:")
            emit(n.no, depth + 1)

        emit(0, 1)


def _python_test(name: str, n: Node) -> str:
    if n.op == "==" and n.value is True:
        return name
    if n.op == "in":
        return f"{name} in {tuple(plain(v) for v in n.value)!r}"
    return f"{name} {n.op} {plain(n.value)!r}"


def holds(node: Node, v: Any) -> bool:
    if node.op == "<=":
        return v <= node.value
    return v in node.value if node.op == "in" else v == node.value


def plain(v: Any) -> Any:
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, tuple):
        return [plain(x) for x in v]
    return v


def identifier(name: str) -> str:
    text = "".join(c if c.isalnum() or c == "_" else "_" for c in name)
    text = text if text and not text[0].isdigit() else f"f_{text}"
    return f"{text}_" if keyword.iskeyword(text) else text


def fresh_name(name: str, taken: set[str]) -> str:
    """``name`` with ``_`` appended until neither it nor its Python name is ``taken``
    (world variables ``lambda`` and ``lambda_`` are both ``lambda_`` in Python)."""
    while name in taken or identifier(name) in taken:
        name += "_"
    taken |= {name, identifier(name)}
    return name


def _leaf_json(decision: Any, randomised: bool) -> dict[str, Any]:
    if not randomised:
        return {"action": decision}
    if decision is None:
        return {"action": None}
    actions, weights, stay, inside, keep, kept = decision
    out = {"actions": {a: w for a, w, k in _mix(actions, weights, keep) if w > 0 and not k},
           "stay": stay, "inside": list(inside)}
    if any(keep):  # the keep choice, and what a run that drew it plays for ever
        out |= {"keep": sum(w for _, w, k in _mix(actions, weights, keep) if k),
                "kept": list(kept)}
    return out


def _mix(actions: Sequence[str], weights: Sequence[float],
         keep: Sequence[bool]) -> list[tuple[str, float, bool]]:
    """A randomised leaf's choices: action, probability, whether it is the keep choice."""
    flags = keep or (False,) * len(actions)
    return list(zip(actions, weights, flags, strict=True))


def _leaf_text(decision: Any, randomised: bool) -> str:
    if not randomised or decision is None:
        return "stop (lost)" if decision is None else str(decision)
    actions, weights, stay, _, keep, kept = decision
    parts = [f"{a}: {w:.3g}" for a, w, k in _mix(actions, weights, keep) if w > 0 and not k]
    parts += [f"keep: {w:.3g} ({', '.join(kept) or 'any'} for ever)"
              for _, w, k in _mix(actions, weights, keep) if w > 0 and k]
    return "\n".join(parts + ([f"stay: {stay:.3g}"] if stay else []))


def _leaf_python(decision: Any, randomised: bool) -> str:
    if not randomised or decision is None:
        return repr(decision)
    actions, weights, stay, _, keep, kept = decision
    mix: dict[Any, float] = {a: w for a, w, k in _mix(actions, weights, keep) if w > 0 and not k}
    for _, w, k in _mix(actions, weights, keep):
        if k and w > 0:
            mix[("keep", *kept)] = w
    if stay:
        mix[None] = stay
    return repr(mix)


def decision_label(d: Decision, randomised: bool) -> Hashable:
    """What a leaf holds for the decision ``d``: None where the task is lost; the
    action (``"fallback"``: the world state's first) or, randomised, the distribution
    ``(actions, weights, stay, inside, keep, kept)``."""
    if d.lost:
        return None
    if not randomised:
        return d.actions[0] if d.actions else "fallback"
    w = tuple(float(x) for x in (d.weights if d.weights is not None else ()))
    return (d.actions, w, float(d.stay), d.inside, d.keep, d.kept)


def label_decision(label: Any, randomised: bool) -> Decision:
    """The controller's decision a leaf's ``label`` stands for (the inverse of
    :func:`decision_label`)."""
    if label is None:
        return Decision((), lost=True)
    if not randomised:
        return Decision((label,))
    actions, weights, stay, inside, keep, kept = label
    return Decision(actions, np.asarray(weights, dtype=np.float64), stay, inside,
                    keep=keep, kept=kept)

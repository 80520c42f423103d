"""The product of several automata read in lock step: the task's and each constraint's.

A joint state is a tuple ``(q_task, q_1, ..., q_k)`` of component states; reading a
letter steps every component.  A component that has accepted or rejected stays there
(its state is absorbing), so the run keeps tracking the undecided components after
the others are decided.  A joint state in which every component is decided is
*terminal*: it is absorbing in the joint automaton (a self-loop on every letter) and
the constrained solver merges the product states that carry it into one absorbing
state per verdict tuple.

The joint automaton is a :class:`~mitld_lp.automata.dta.DTA` without an accepting or
rejecting state (``accepting = rejecting = None``), so :func:`mitld_lp.product.product`
builds it as it builds any task's; :class:`Joint` says what each joint state means.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from mitld_lp.automata.dta import DTA, OPEN, Diagram
from mitld_lp.logic.syntax import conj

__all__ = ["Joint", "joint_automaton", "ACCEPTED", "REJECTED", "UNDECIDED"]

ACCEPTED, REJECTED, UNDECIDED = 1, 0, -1
"""A component's verdict in a joint state."""


@dataclass(frozen=True, slots=True)
class Joint:
    """The joint automaton and, per joint state, its components' states and verdicts.

    Attributes:
        dta: the joint automaton (state ``j`` is the tuple ``components[j]``).
        parts: the component automata, the task's first.
        components: per joint state, the component states.
        verdicts: per joint state, per component, :data:`ACCEPTED`, :data:`REJECTED` or
            :data:`UNDECIDED`.
    """

    dta: DTA
    parts: tuple[DTA, ...]
    components: tuple[tuple[int, ...], ...]
    verdicts: tuple[tuple[int, ...], ...]

    def terminal(self, j: int) -> bool:
        """Every component of joint state ``j`` is decided."""
        return UNDECIDED not in self.verdicts[j]


def _verdict(dta: DTA, q: int) -> int:
    return ACCEPTED if q == dta.accepting else REJECTED if q == dta.rejecting else UNDECIDED


def _graft(d: Diagram, leaf) -> Diagram:
    """``d`` with each leaf ``l`` replaced by the diagram ``leaf(l)``."""
    if isinstance(d, int):
        return leaf(d)
    p, low, high = d
    return (p, _graft(low, leaf), _graft(high, leaf))


def _chain(parts: tuple[DTA, ...], t: tuple[int, ...], i: int, prefix: tuple[int, ...],
           intern) -> Diagram:
    """The diagram of joint state ``t`` from component ``i`` on: component ``i``'s diagram
    whose leaves continue with the next component, the last ones interned as tuples."""
    if i == len(parts):
        return intern(prefix)
    return _graft(parts[i].delta[t[i]],
                  lambda leaf: _chain(parts, t, i + 1, (*prefix, leaf), intern))


def joint_automaton(parts: Sequence[DTA], *, max_states: int = 200_000) -> Joint:
    """The reachable lock-step product of ``parts`` (see the module docstring); raises
    ``ValueError`` past ``max_states`` joint states."""
    parts = tuple(parts)
    index: dict[tuple[int, ...], int] = {}
    order: list[tuple[int, ...]] = []

    def intern(t: tuple[int, ...]) -> int:
        j = index.get(t)
        if j is None:
            if len(order) >= max_states:
                raise ValueError(f"the joint automaton has more than {max_states:,} states")
            j = index[t] = len(order)
            order.append(t)
        return j

    intern(tuple(p.initial for p in parts))
    delta: list[Diagram] = []
    verdicts: list[tuple[int, ...]] = []
    head = 0
    while head < len(order):
        t = order[head]
        v = tuple(_verdict(p, q) for p, q in zip(parts, t, strict=True))
        verdicts.append(v)
        if UNDECIDED not in v:
            delta.append(head)  # terminal: absorbing
        else:
            delta.append(_chain(parts, t, 0, (), intern))
        head += 1
    atoms = tuple(sorted({a for p in parts for a in p.atoms}))
    dta = DTA(
        formula=conj(*(p.formula for p in parts)),
        atoms=atoms,
        states=tuple(conj(*(p.states[q] for p, q in zip(parts, t, strict=True))) for t in order),
        initial=0,
        accepting=None,
        rejecting=None,
        delta=tuple(delta),
        kinds=tuple(OPEN for _ in order),
        fragment="co-safe",
    )
    return Joint(dta, parts, tuple(order), tuple(verdicts))

"""Growing a decision tree top-down (the split of highest information gain, as CART and
dtControl do) until every leaf holds a decision every sample below it allows
(:func:`grow`; used by :func:`mitld_lp.running.tree.tree_of`)."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Hashable
from typing import Any

from mitld_lp.running.tree_format import Node, holds

__all__ = ["grow"]


def _sort_key(v: Any) -> tuple[str, Any]:
    if isinstance(v, bool | int | float):
        return ("0", float(v))
    return ("1", repr(v))


def _entropy(counts: Counter[Any] | dict[Any, int], n: int) -> float:
    return -sum(k / n * math.log2(k / n) for k in counts.values() if k)


def _order(d: Hashable) -> tuple[bool, str]:
    return (d is None, repr(d))


def grow(rows: list[tuple[Any, ...]], allowed: list[frozenset[Hashable]], idx: list[int],
          nodes: list[Node], categorical: frozenset[int] = frozenset()) -> int:
    """Append the subtree of the samples ``idx`` (each with its set of allowed
    decisions) to ``nodes``; return its root.  A leaf holds a decision every sample
    below it allows; a split is chosen on each sample's most common allowed decision
    (dtControl's "max-freq" determinisation)."""
    at = len(nodes)
    nodes.append(Node())
    common = frozenset.intersection(*(allowed[i] for i in idx)) if idx else frozenset()
    if common:
        nodes[at] = Node(decision=min(common, key=_order))
        return at
    freq = Counter(d for i in idx for d in allowed[i])
    ranked = sorted(freq, key=lambda d: (-freq[d], _order(d)))
    place = {d: k for k, d in enumerate(ranked)}
    labels = {i: min(allowed[i], key=place.__getitem__) for i in idx}
    best = _best_split(rows, labels, idx, Counter(labels.values()), categorical)
    if best is None:  # equal features, no common decision: cannot happen on a product
        raise ValueError("two reachable states with the same features take different "
                         "decisions; the features do not describe the controller's state")
    feature, op, value = best
    probe = Node(feature, op, value)
    yes = [i for i in idx if holds(probe, rows[i][feature])]
    no = [i for i in idx if not holds(probe, rows[i][feature])]
    y = grow(rows, allowed, yes, nodes, categorical)
    n = grow(rows, allowed, no, nodes, categorical)
    nodes[at] = Node(feature, op, value, y, n)
    return at


def _best_split(rows: list[tuple[Any, ...]], labels: dict[int, Hashable], idx: list[int],
                counts: Counter[Any], categorical: frozenset[int] = frozenset()
                ) -> tuple[int, str, Any] | None:
    n = len(idx)
    base = _entropy(counts, n)
    best: tuple[float, int, int, str, Any] | None = None
    for f in range(len(rows[idx[0]])):
        values = [rows[i][f] for i in idx]
        distinct = set(values)
        if len(distinct) < 2:
            continue
        numeric = f not in categorical and all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in distinct)
        ordered = sorted(distinct, key=_sort_key)
        by_value: dict[Any, Counter[Any]] = {}
        for i, v in zip(idx, values, strict=True):
            by_value.setdefault(v, Counter())[labels[i]] += 1
        candidates: list[tuple[str, Any, Counter[Any]]] = []
        if numeric:
            left: Counter[Any] = Counter()
            for v in ordered[:-1]:
                left = left + by_value[v]
                candidates.append(("<=", v, left))
        else:
            candidates += [("==", v, by_value[v]) for v in ordered]
            if len(ordered) == 2:
                candidates = candidates[1:]  # one test splits a pair
            else:  # the values grouped by their most common decision: "in {...}"
                groups: dict[Hashable, list[Any]] = {}
                for v in ordered:
                    top = max(by_value[v], key=lambda d: (by_value[v][d], repr(d)))
                    groups.setdefault(top, []).append(v)
                for members in groups.values():
                    if 1 < len(members) < len(ordered):
                        inside = sum((by_value[v] for v in members), Counter())
                        candidates.append(("in", tuple(members), inside))
        for op, v, inside in candidates:
            k = sum(inside.values())
            rest = counts - inside
            gain = base - (k / n) * _entropy(inside, k) - ((n - k) / n) * _entropy(rest, n - k)
            key = (round(gain, 12), -f)
            if best is None or key > best[:2]:
                best = (key[0], key[1], f, op, v)
    if best is None:
        return None
    _, _, f, op, v = best
    return f, op, v

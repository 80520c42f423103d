"""The own explorer of a PRISM MDP: :mod:`~mitld_lp.worlds.prism_compile`'s tables run by
:mod:`~mitld_lp.worlds.prism_kernels`' compiled breadth-first search, read into the
:class:`~mitld_lp.worlds.prism_tables.Tables` Storm's build gives (the same states in
the same order, the same choices, rows, labels and names), so that nothing after the
load changes.

Which builder the load uses (:func:`chosen_builder`): the environment variable
``MITLD_PRISM_BUILDER`` = ``storm`` or ``own`` forces one; by default (``auto``) the own
explorer runs where its kernel's machine code is cached on disk (a first compile, about
10 s, is paid only where asked for: ``own``, the tests, ``experiments/explore_vs_storm.py``).
It declines, and Storm builds, where the program is outside the fragment
(:class:`~mitld_lp.worlds.prism_compile.Unsupported`), where an update leaves a
variable's range or a probability is negative (Storm's build then refuses it in its own
words), where two choices of one state would carry one name (Storm's choice origins name
them), or where event effects are asked for; :attr:`Explored.reason` says why (logged
at debug level).
"""

from __future__ import annotations

import itertools
import logging
import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from mitld_lp.worlds.prism_compile import Compiled, Unsupported, compile_program
from mitld_lp.worlds.prism_labels import flag_labels
from mitld_lp.worlds.prism_program import SUM_TOLERANCE, storm_quiet
from mitld_lp.worlds.prism_tables import DEADLOCK_ACTION, DECIDED_ACTION, Tables, Valuations
from mitld_lp.worlds.successors import Normalisation, checked_rows, normalise_rows
from mitld_lp.worlds.table import LATE, LateNames

__all__ = ["OWN_BYTES_PER_STATE", "BUILDER_ENV", "Explored", "KnownNames", "PackedValuations",
           "chosen_builder", "decoded", "explore_program", "explore_tables", "kernel_ready",
           "label_values", "sync_radix", "terminal_expression", "compile_kernels",
           "WARM_PROGRAM"]

log = logging.getLogger("mitld_lp.worlds.prism")

BUILDER_ENV = "MITLD_PRISM_BUILDER"
"""The environment variable that forces a builder: ``storm``, ``own`` or ``auto``."""

OWN_BYTES_PER_STATE = 512
"""Memory per state of the own explorer's build at its peak, for the budget: the packed
state and its hash slot (about 40 bytes), the growing arrays of choices and branches
(doubled: up to twice their 16 bytes per branch at ten branches a state), the tables'
copies and the product's later reading of them, rounded up."""

NAMES_BLOCK = 1 << 17
"""The choices whose first commands :func:`_naming` reads at a time."""

_STATUS = {1: "an update leaves a variable's range", 2: "a probability is negative",
           3: "more states than max_states"}


@dataclass
class Explored:
    """The own explorer's raw build: ``keys`` (``n x words`` packed states, flat), the
    offsets and branches as in :class:`Tables`, each choice's command (``origin``; -1 a
    deadlock's self-loop, -2 a decided state's, ``-3 - i``: a synchronised choice whose
    commands :meth:`commands` reads from ``i``, ``sync_base`` and the layout); a state's
    values are decoded from ``keys`` when asked for (:attr:`values`)."""

    compiled: Compiled
    choices: np.ndarray
    branches: np.ndarray
    targets: np.ndarray
    probabilities: np.ndarray
    origin: np.ndarray
    keys: np.ndarray
    layout: dict[str, Any]
    sync_base: np.ndarray
    radix: tuple[list[list[int]], np.ndarray] | None = None

    @property
    def values(self) -> np.ndarray:
        """``n x variables`` values in the compiled order, the narrowest type."""
        return decoded(self.keys, self.layout, list(range(len(self.compiled.names))))

    def first_commands(self, lo: int = 0, hi: int | None = None) -> np.ndarray:
        """Each choice's (from ``lo`` to ``hi``) first command (its name's): ``origin``
        where a command, the first module's of a synchronised one, -1 for the self-loops."""
        origin = self.origin[lo:hi]
        first = np.where(origin >= 0, origin, -1)
        sync = np.flatnonzero(origin <= -3)
        if sync.size:
            i = -3 - origin[sync]
            a = np.searchsorted(self.sync_base, i, side="right") - 1
            high = self._radix()[1]  # the first module's digit's weight per action
            slot = np.asarray(self.layout["sync_start"])[a]
            lo = np.asarray(self.layout["mod_start"])[slot]
            first[sync] = np.asarray(self.layout["sync_cmd"])[lo + (i - self.sync_base[a])
                                                               // high[a]]
        return first

    def commands(self, c: int) -> list[int]:
        """Choice ``c``'s commands (one, or one a module of a synchronised choice)."""
        o = int(self.origin[c])
        if o >= 0:
            return [o]
        i = -3 - o
        a = int(np.searchsorted(self.sync_base, i, side="right")) - 1
        r = i - int(self.sync_base[a])
        counts = self._radix()[0][a]
        slots = range(int(self.layout["sync_start"][a]), int(self.layout["sync_start"][a + 1]))
        digits = []
        for k in reversed(counts):
            digits.append(r % k)
            r //= k
        mod_start, sync_cmd = self.layout["mod_start"], self.layout["sync_cmd"]
        return [int(sync_cmd[int(mod_start[s]) + d]) for s, d in zip(slots, reversed(digits),
                                                                     strict=True)]

    def _radix(self) -> tuple[list[list[int]], np.ndarray]:
        """Per action, its modules' numbers of commands, and the first one's weight."""
        if self.radix is None:
            self.radix = sync_radix(self.layout["sync_start"], self.layout["mod_start"])
        return self.radix


def sync_radix(sync_start: Any, mod_start: Any) -> tuple[list[list[int]], np.ndarray]:
    """Per synchronised action, its modules' numbers of commands of it, and the weight
    of the first module's digit (the product of the others' numbers)."""
    counts = [[int(mod_start[s + 1] - mod_start[s]) for s in range(int(sync_start[a]),
                                                                  int(sync_start[a + 1]))]
              for a in range(len(sync_start) - 1)]
    return counts, np.array([math.prod(k[1:]) for k in counts] or [1], dtype=np.int64)


def decoded(keys: np.ndarray, layout: dict[str, Any], columns: list[int]) -> np.ndarray:
    """The values of the variables ``columns`` of each packed state of ``keys``, one
    column at a time, in the narrowest type holding every variable's range."""
    words = int(layout["words"])
    packed = keys.reshape(-1, words)
    out = np.empty((packed.shape[0], len(columns)),
                   dtype=_value_type(layout["low"], layout["high"]))
    for j, v in enumerate(columns):
        field = packed[:, layout["word"][v]] >> layout["shift"][v]
        field &= (1 << int(layout["width"][v])) - 1
        field += layout["low"][v]
        out[:, j] = field
    return out


ALONE = 4096
"""States a :class:`PackedValuations` decodes alone before it decodes every state's."""


class PackedValuations(Valuations):
    """:class:`~mitld_lp.worlds.prism_tables.Valuations` kept as the explorer's packed
    states (``words`` int64 a state: csma 4-2's 19 variables in one word) and decoded
    when first read whole (a solve reads none; the decode and its copies were a third of
    the explorer's tables step and its largest array); a few states asked for (the
    initial one, a policy's) are decoded alone."""

    def __init__(self, keys: np.ndarray, layout: dict[str, Any], columns: list[int],
                 booleans: tuple[int, ...]) -> None:
        self.keys, self.layout, self.columns = keys, layout, columns
        self.booleans = booleans
        self._values: np.ndarray | None = None
        self._alone = 0  # the states decoded alone so far

    @property  # type: ignore[override]
    def values(self) -> np.ndarray:
        if self._values is None:
            self._values = decoded(self.keys, self.layout, self.columns)
            self.keys = self.keys[:0]
        return self._values

    def __len__(self) -> int:
        if self._values is not None:
            return int(self._values.shape[0])
        return int(self.keys.size // int(self.layout["words"]))

    def _of(self, at: Any) -> np.ndarray:
        """The values of the states ``at`` (an index array or a slice): decoded from
        their packed states alone until every state's are, or until :data:`ALONE`
        states were (a reader going through many states one by one: every state's
        then, each a row read after)."""
        if self._values is None and self._alone >= ALONE:
            return self.values[at]
        if self._values is not None:
            return self._values[at]
        packed = self.keys.reshape(-1, int(self.layout["words"]))[at]
        self._alone += packed.shape[0]
        return decoded(packed.reshape(-1), self.layout, self.columns)

    def rows(self, indices: np.ndarray) -> list[Any]:
        return self._tuples(self._of(np.asarray(indices, dtype=np.int64)))

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return tuple(self._tuples(self._of(i)))
        i = int(i)
        if not -len(self) <= i < len(self):
            raise IndexError(f"state {i} of {len(self)}")
        return self._tuples(self._of(np.array([i % len(self)])))[0]


def chosen_builder() -> str:
    """``storm``, ``own`` or ``auto`` from :data:`BUILDER_ENV` (``auto`` if unset);
    ``ValueError`` for another value."""
    value = os.environ.get(BUILDER_ENV, "auto").strip().lower() or "auto"
    if value not in ("storm", "own", "auto"):
        raise ValueError(f"{BUILDER_ENV}={value!r}: expected storm, own or auto")
    return value


def kernel_ready() -> bool:
    """Whether the explorer's machine code can be had without a compile."""
    from mitld_lp.util import kernel_loader

    return all(kernel_loader.module_cached("mitld_lp.worlds.prism_kernels", name)
               for name in ("explore", "label_flags", "rehash"))


WARM_PROGRAM = """mdp
module warm
  x : [0..2] init 0;
  b : bool init false;
  [go] x<2 -> 0.5:(x'=x+1) + 0.5:(b'=!b);
  [] x=2 -> (x'=0);
endmodule
label "done" = x=2 & b;
"""
"""A program whose build calls both of the explorer's kernels (a state's choices and a
label's flags): :func:`compile_kernels` builds it."""


def compile_kernels(stormpy: Any) -> bool:
    """Compile the explorer's kernels into the cache on disk, by building
    :data:`WARM_PROGRAM` with them and growing a small hash table (``rehash``, which a
    build of more than 2**16 states calls: left out, a large model's first load after
    ``warm`` compiled it, 1 s of CPU); the command line's ``warm``. False where they
    were cached already (nothing compiled)."""
    import tempfile
    from pathlib import Path

    if kernel_ready():
        return False
    with tempfile.TemporaryDirectory() as folder:  # stormpy parses files only
        path = Path(folder) / "warm.prism"
        path.write_text(WARM_PROGRAM, encoding="ascii")
        with storm_quiet():
            program = stormpy.parse_prism_program(str(path))
    compiled = compile_program(program, None)
    built = explore_program(compiled, 100)
    assert not isinstance(built, str), built  # the program is in the fragment
    label_values(built, [compiled.label_expr[compiled.labels.index("done")]])
    i64 = np.int64  # a build past 2**16 states grows its table: rehash, as explore calls it
    _kernels().rehash(np.zeros(2, dtype=i64), i64(1), i64(2), i64(4))
    return True


def _kernels() -> Any:
    from mitld_lp.worlds import prism_kernels

    return prism_kernels


def terminal_expression(stormpy: Any, plain: Any, terminal: str) -> Any:
    """The decided-states condition ``terminal`` (a PRISM expression over ``plain``'s
    variables) as a stormpy ``Expression``; None for ``""``."""
    if not terminal:
        return None
    with storm_quiet():
        prop = stormpy.parse_properties(f"Pmax=? [F {terminal}]", plain)[0]
    inner = prop.get_raw_formula().subformula.subformula
    if not hasattr(inner, "get_expression"):
        raise Unsupported(f"the decided-states condition {terminal} is not one expression")
    return inner.get_expression()


def explore_program(compiled: Compiled, max_states: int, guess: int = 1 << 16,
                    ) -> Explored | str:
    """The own build of ``compiled``; a reason string where it declines (a status).
    The arrays start at ``guess`` states (and four choices and branches a state), are
    doubled where the kernel stops for room (a new array written only as far as used)
    and cut to their use in place (``resize``: no second copy)."""
    k = _kernels()
    a = compiled.arrays()
    words = int(a["words"])
    max_states = min(max_states, (1 << 31) - 1)  # the hash table's int32 slots
    counts, _ = sync_radix(a["sync_start"], a["mod_start"])
    sizes = [math.prod(x) for x in counts]
    if sum(sizes) >= 1 << 60:
        return "too many combinations of synchronised commands to number"
    sync_base = np.array([0] + list(itertools.accumulate(sizes)), dtype=np.int64)
    i64 = np.int64
    keys = np.empty(guess * words, dtype=i64)
    # a power of two: the probe's mask (a table of another size leaves slots unreachable,
    # and a probe over the rest may never end)
    table = np.full(1 << max(2, (4 * guess - 1).bit_length()), -1, dtype=np.int32)
    choices = np.empty(guess + 1, dtype=i64)
    branches = np.empty(4 * guess + 1, dtype=i64)
    targets = np.empty(4 * guess, dtype=i64)
    probs = np.empty(4 * guess, dtype=np.float64)
    origin = np.empty(4 * guess, dtype=i64)
    pos = np.zeros(7, dtype=i64)
    while True:
        status = int(k.explore(
            a["code"], a["consts"], a["starts"], a["word"], a["shift"], a["width"], a["low"],
            a["high"], a["initial"], a["cmd_guard"], a["conj"], a["cmd_updates"], a["upd_prob"],
            a["upd_assign"], a["asg_var"], a["asg_expr"], i64(compiled.n_async),
            a["sync_start"], a["mod_start"], a["sync_cmd"], sync_base, i64(compiled.terminal),
            i64(words), i64(max_states), keys, table, choices, branches, targets, probs,
            origin, pos))
        if status == k.REHASH:
            size = 2 * table.size
            del table  # the old slots freed before the new are filled
            table = k.rehash(keys, i64(pos[1]), i64(words), i64(size))
        elif status == k.FULL:  # every array at least half full doubled
            n, m, b = (int(x) for x in pos[1:4])
            before = (keys, choices, branches, origin, targets, probs)
            keys = _doubled(keys, n * words)
            choices = _doubled(choices, n + 1)
            branches, origin = _doubled(branches, m + 1), _doubled(origin, m)
            targets, probs = _doubled(targets, b), _doubled(probs, b)
            if all(x is y for x, y in zip(before, (keys, choices, branches, origin, targets,
                                                   probs), strict=True)):
                # none half full: the state stopped at needs more than the half left of
                # its choices' or branches' arrays (a small guess), so those doubled
                branches, origin = _doubled(branches, m + 1, True), _doubled(origin, m, True)
                targets, probs = _doubled(targets, b, True), _doubled(probs, b, True)
        elif status != k.OK:
            return f"{_STATUS[status]} (state {int(pos[5])}, command {int(pos[6])})"
        else:
            break
    n, m, b = (int(x) for x in pos[1:4])
    del table
    for array, used in ((keys, n * words), (choices, n + 1), (branches, m + 1),
                        (origin, m), (targets, b), (probs, b)):
        array.resize(used, refcheck=False)  # in place: realloc gives the rest back
    return Explored(compiled, choices, branches, targets, probs, origin, keys, a, sync_base)


def _value_type(low: np.ndarray, high: np.ndarray) -> Any:
    """The narrowest signed integer type holding every variable's range (int64 at most):
    a state's values, eight bytes a variable in int64, were the largest array of a build
    with many variables (csma 4-2: 13 a state)."""
    lo, hi = (int(low.min()), int(high.max())) if low.size else (0, 0)
    for kind in (np.int8, np.int16, np.int32):
        if np.iinfo(kind).min <= lo and hi <= np.iinfo(kind).max:
            return kind
    return np.int64


def _doubled(array: np.ndarray, used: int, force: bool = False) -> np.ndarray:
    """``array`` twice as long (its first ``used`` entries kept) when at least half full
    (every one, so that a state needing more than half the room gets it in time), or
    ``force``d."""
    if 2 * used < array.size and not force:
        return array
    out = np.empty(2 * array.size, dtype=array.dtype)
    out[:used] = array[:used]
    return out


def label_values(built: Explored, exprs: list[int]) -> np.ndarray:
    """``n x len(exprs)`` flags: each state's truth of each compiled expression."""
    a = built.layout
    return _kernels().label_flags(a["code"], a["consts"], a["starts"], built.keys,
                                  a["words"], a["word"], a["shift"], a["width"], a["low"],
                                  np.asarray(exprs, dtype=np.int64))


def explore_tables(stormpy: Any, plain: Any, where: str, chosen: frozenset[str],
                   events: frozenset[str], terminal: str, max_states: int,
                   condition: Any = None) -> tuple[Tables | None, str]:
    """The own build of ``plain`` (the program with its constants) as :class:`Tables`,
    as :func:`~mitld_lp.worlds.prism_build.build_tables` would read Storm's; or
    ``(None, reason)`` where it declines (the module docstring).  Without ``stormpy``
    (the own parse's program), ``condition`` is ``terminal`` as an expression."""
    if events:
        return None, "event effects"
    try:
        compiled = compile_program(plain, condition if stormpy is None else
                                   terminal_expression(stormpy, plain, terminal))
    except Unsupported as exc:
        return None, str(exc)
    built = explore_program(compiled, max_states)  # past it: Storm's build says so
    if isinstance(built, str):
        return None, built
    n = len(built.choices) - 1
    naming = _naming(plain, compiled, built, terminal)
    if isinstance(naming, str):
        return None, naming
    action_names, action_index = naming
    decided = int(np.count_nonzero(built.origin == -2))
    built.origin = built.origin[:0]  # read by the names only: freed before the labels
    lengths = np.diff(built.branches)
    bad, total, branch_row = checked_rows(lengths, built.probabilities, SUM_TOLERANCE)
    if bad.size:
        return None, "a distribution that is not one (Storm's build refuses it)"
    probabilities, rows, largest = normalise_rows(lengths, built.probabilities,
                                                  (total, branch_row))
    del lengths, total, branch_row  # a choice's and a branch's each: freed before the labels
    normalised = None if rows == 0 else Normalisation(where, rows, largest, SUM_TOLERANCE)
    if normalised is not None:
        log.info("%s", normalised)
    labels = sorted(chosen)
    exprs = [compiled.label_expr[compiled.labels.index(x)] for x in labels]
    flags = label_values(built, exprs) if labels else np.zeros((n, 0), dtype=bool)
    label_sets, label_index = flag_labels(flags, labels)
    del flags
    order = [compiled.names.index(x) for x in sorted(compiled.names)]  # program_head's
    booleans = tuple(k for k, v in enumerate(order) if v in compiled.booleans)
    states = PackedValuations(built.keys, built.layout, order, booleans)
    tables = Tables(
        variables=tuple(compiled.names[v] for v in order), states=states, initial=0,
        label_sets=label_sets, label_index=label_index, choices=built.choices,
        branches=built.branches, targets=built.targets, probabilities=probabilities,
        action_names=action_names, action_index=action_index,
        effects={}, decided=decided,
        normalised=normalised, checked=True)
    return tables, ""


def _naming(plain: Any, compiled: Compiled, built: Explored, terminal: str,
            ) -> tuple[Any, np.ndarray] | str:
    """``(action_names, action_index)`` as :func:`~mitld_lp.worlds.prism_build.build_tables`
    names Storm's build of ``plain`` (whole, without events, its valuations deferred):
    by the choices' labels, the distinct ones sorted, then ``deadlock`` and, with a
    decided-states condition, ``decided`` (a program whose commands all have actions and
    no module two of one action); or every choice but those self-loops named when first
    read (:class:`KnownNames`; :func:`~mitld_lp.worlds.prism_names.late_names`).  A
    reason where neither applies or two choices of a state would share a name."""
    from mitld_lp.worlds.prism_names import late_names
    from mitld_lp.worlds.prism_origins import may_share_names, needs_origins

    late = late_names(plain)
    if needs_origins(plain) and not late:
        return "choices named from Storm's choice origins"
    m = len(built.branches) - 1
    if late and m >= LATE:
        return "too many choices for late names"
    cmd_names = list(dict.fromkeys(compiled.cmd_name))
    of_cmd = np.array([cmd_names.index(x) for x in compiled.cmd_name] or [0], dtype=np.int32)
    of = np.empty(m, dtype=np.int32)
    for lo in range(0, m, NAMES_BLOCK):  # in blocks: a block's temporaries, not a build's
        first = built.first_commands(lo, lo + NAMES_BLOCK)
        of[lo:lo + first.size] = np.where(first < 0, -1, of_cmd[np.maximum(first, 0)])
    loop = of < 0
    clash = _clashes(built, of, len(cmd_names)) if may_share_names(plain) else None
    if clash is not None and clash.size and not late:
        return "two choices of one state with one name (Storm's choice origins name them)"
    known = (DEADLOCK_ACTION,) + ((DECIDED_ACTION,) if terminal else ())
    if clash is not None and clash.size:  # told apart by their commands, go@m_cmd2
        of, cmd_names = _told_apart(built, compiled, of, cmd_names, clash)
        if _clashes(built, of, len(cmd_names)).size:
            return "two choices of one state with one name after their commands"
    if late:
        index = np.arange(LATE, LATE + m, dtype=np.int32)  # int32, as Storm's build's
        index[loop] = 0
        index[built.origin == -2] = len(known) - 1
        return KnownNames(known, of, cmd_names, index), index
    table = sorted(set(cmd_names)) + list(known)
    distinct = {x: k for k, x in enumerate(dict.fromkeys(table))}
    remap = np.array([distinct[x] for x in cmd_names] + [distinct[DEADLOCK_ACTION]]
                     + [distinct[known[-1]]], dtype=np.int32)
    code = np.where(built.origin == -1, len(cmd_names),
                    np.where(built.origin == -2, len(cmd_names) + 1, of))
    used = sorted(set(cmd_names) & {cmd_names[k] for k in np.unique(of[of >= 0]).tolist()})
    if used != sorted(set(cmd_names)):  # only the labels some choice has, as Storm's
        return _relabel(used, known, remap, cmd_names, code)
    return tuple(distinct), remap[code]


def _clashes(built: Explored, of: np.ndarray, k: int) -> np.ndarray:
    """The choices that share their name (``of``, ``k`` names) with another of their
    state, ascending."""
    n = len(built.choices) - 1
    kind = np.int32 if (n + 1) * (k + 1) < 1 << 31 else np.int64  # the narrower when it fits
    key = np.repeat(np.arange(0, n * (k + 1), k + 1, dtype=kind), np.diff(built.choices))
    key += of
    key += 1
    # the common case, no two alike, told without the order's arrays; a stable sort: the
    # keys come in a run per state, merged in about one pass
    ordered = np.sort(key, kind="stable")
    if not (ordered[1:] == ordered[:-1]).any():
        return np.empty(0, dtype=np.int64)
    del ordered
    order = np.argsort(key, kind="stable")
    same = key[order][1:] == key[order][:-1]
    twice = np.zeros(key.size, dtype=bool)
    twice[order[1:][same]] = True
    twice[order[:-1][same]] = True
    return np.flatnonzero(twice & (of >= 0))


def _told_apart(built: Explored, compiled: Compiled, of: np.ndarray, names: list[str],
                clash: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """The ``clash`` choices renamed ``<name>@<their commands>`` (their
    ``<module>_cmd<k>`` in Storm's global order, joined by ``+``), as
    :func:`mitld_lp.worlds.prism_names.origin_codes` names them."""
    of, names = of.copy(), list(names)
    position = {x: k for k, x in enumerate(names)}
    # a choice's commands, and so its name, are its origin's: each distinct one named
    # once, in the order the clashing choices first show them (zeroconf_dl: 2,384
    # choices, a few origins)
    origins, first_at, inverse = np.unique(built.origin[clash], return_index=True,
                                           return_inverse=True)
    renamed = np.empty(origins.size, dtype=of.dtype)
    for j in np.argsort(first_at, kind="stable").tolist():
        c = int(clash[first_at[j]])
        text = "+".join(compiled.cmd_text[x] for x in sorted(
            built.commands(c), key=lambda x: compiled.cmd_global[x]))
        name = f"{names[int(of[c])]}@{text}"
        k = position.setdefault(name, len(position))
        if k == len(names):
            names.append(name)
        renamed[j] = k
    of[clash] = renamed[np.asarray(inverse).reshape(-1)]
    return of, names


def _relabel(used: list[str], known: tuple[str, ...], remap: np.ndarray,
             cmd_names: list[str], code: np.ndarray) -> tuple[Any, np.ndarray]:
    """:func:`_naming`'s labels where some action has no choice: the used ones only."""
    distinct = {x: k for k, x in enumerate(dict.fromkeys(used + list(known)))}
    again = np.array([distinct.get(x, -1) for x in cmd_names] + [distinct[DEADLOCK_ACTION]]
                     + [distinct[known[-1]]], dtype=np.int32)
    return tuple(distinct), again[code]


class KnownNames(LateNames):
    """A world's names where every choice but the deadlock and decided self-loops has
    the id ``LATE + c`` (as Storm's build names them when first read,
    :class:`~mitld_lp.worlds.prism_names.DeferredNames`), all known already: choice
    ``c``'s is ``names[of[c]]``."""

    def __init__(self, known: tuple[str, ...], of: np.ndarray, names: list[str],
                 index: np.ndarray) -> None:
        self.known, self.of, self.names, self.index = known, of, tuple(names), index

    def names_of(self, choices: np.ndarray) -> tuple[np.ndarray, tuple[str, ...]]:
        choices = np.asarray(choices, dtype=np.int64)
        of = self.of[choices]
        codes = np.where(of >= 0, len(self.known) + of, self.index[choices])
        return codes.astype(np.int64), self.known + self.names

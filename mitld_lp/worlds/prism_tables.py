"""Storm's sparse MDP copied into numpy arrays, with no Python loop over states.

The transition structure comes from Storm's own binary export (UMB: the offsets of each
state's choices and of each choice's branches, the branch targets and probabilities, as
little-endian 64-bit arrays in an uncompressed tar, its members found from the tar
headers: :mod:`mitld_lp.worlds.prism_archive`), read with :func:`numpy.fromfile`;
the state valuations from the same archive's bit-packed records (Storm's per-variable
calls, which make a Python list of each variable's values, where the layout is another);
each choice's label from the same archive's actions (Storm's per-label bit vectors where
they disagree with it), or its choice origin where the choices are named from the
commands they come from (:mod:`mitld_lp.worlds.prism_origins`), state labels from the
same archive's bit vectors where they agree with Storm's own (else Storm's per-label
calls, a bit vector each).  Each row's sum is computed once, for the check of PRISM's
tolerance and the normalisation, and the table says its rows were checked
(:attr:`Tables.checked`), so the product does not check them again.  Only the choices
that need their commands to be told apart (two enabled commands of one action in a
state) are looked at one by one.
"""

from __future__ import annotations

import json
import logging
import os
import tempfile
from collections.abc import Callable, Hashable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, overload

import numpy as np

from mitld_lp.worlds import WorldError
from mitld_lp.worlds.prism_archive import members as archive_members
from mitld_lp.worlds.prism_archive import read_member
from mitld_lp.worlds.prism_labels import agrees, choice_labels, indices, repeated, state_labels
from mitld_lp.worlds.prism_program import SUM_TOLERANCE, show_sum, storm_quiet
from mitld_lp.worlds.successors import Normalisation, checked_rows, normalise_rows
from mitld_lp.worlds.table import LATE

__all__ = ["Tables", "Valuations", "read_model", "read_export", "read_export_parts",
           "transition_arrays", "label_states",
           "unpack_valuations", "valuations_of", "DEADLOCK_ACTION", "DECIDED_ACTION",
           "OUT_OF_BOUNDS", "OUT_OF_BOUNDS_BIT"]

log = logging.getLogger("mitld_lp.worlds.prism")

DEADLOCK_ACTION = "deadlock"
"""The name of the self-loop Storm adds where no PRISM command is enabled."""

OUT_OF_BOUNDS = "out_of_bounds"
"""Storm's label of its out-of-bounds state (asked for when its checks are off), where an
update that leaves a variable's range goes."""

OUT_OF_BOUNDS_BIT = "_OutOfBoundsBit"
"""The variable Storm adds with that state: not the program's."""

DECIDED_ACTION = "decided"
"""The name of the self-loop of a state where the task is decided (not expanded:
:mod:`mitld_lp.worlds.prism_terminal`)."""

State = tuple[Hashable, ...]


@dataclass(frozen=True, slots=True)
class Tables:
    """The built MDP as arrays (``n`` states, ``m`` choices, ``b`` branches).

    Attributes:
        variables: the PRISM variables, in the order of a state's values.
        states: ``n`` tuples of values (Storm's state order), made when asked for
            (:class:`Valuations`).
        initial: the index of the initial state.
        label_sets: the distinct sets of chosen labels true in a state.
        label_index: ``n`` indices into ``label_sets``: the labels of each state.
        choices: ``n + 1`` offsets: state ``s`` has choices ``choices[s]:choices[s+1]``.
        branches: ``m + 1`` offsets: choice ``c`` has branches ``branches[c]:branches[c+1]``.
        targets, probabilities: the ``b`` branches (state index, probability > 0).
        action_names: the distinct action names.
        action_index: ``m`` indices into ``action_names`` (int32), -1 for an event's choice.
        effects: ``event -> n`` choice indices: the event's choice at each state, -1
            where its command is not enabled.
        decided: how many states were not expanded because the task is decided there.
        normalised: the choices whose probabilities summed to 1 only within PRISM's
            tolerance, divided by their sums (None when there were none).
        unexplored: ``n`` flags, the states found but not expanded by a build with a
            state limit (:func:`mitld_lp.worlds.prism_build.build_tables`); their rows
            are Storm's self-loops, not the program's (None: every state expanded).
        checked: every row was checked to be a distribution within the game's
            tolerance (:data:`~mitld_lp.worlds.successors.PROBABILITY_TOLERANCE`) when
            read (:func:`read_model`, after normalising): the product need not check it
            again (:attr:`mitld_lp.worlds.table.WorldTable.checked`).
    """

    variables: tuple[str, ...]
    states: Valuations
    initial: int
    label_sets: tuple[frozenset[str], ...]
    label_index: np.ndarray
    choices: np.ndarray
    branches: np.ndarray
    targets: np.ndarray
    probabilities: np.ndarray
    action_names: tuple[str, ...]
    action_index: np.ndarray
    effects: Mapping[str, np.ndarray]
    decided: int = 0
    normalised: Normalisation | None = None
    unexplored: np.ndarray | None = None
    checked: bool = False


def transition_arrays(model: Any, where: str) -> tuple[np.ndarray, ...]:
    """``(choices, branches, targets, probabilities)`` of a model Storm built in doubles
    (its UMB export, checked for consistency; branches of probability 0 dropped, negative
    ones kept for :func:`read_model` to refuse)."""
    return read_export(model, where)[0]


def read_export(model: Any, where: str) -> tuple[tuple[np.ndarray, ...],
                                                   dict[str, np.ndarray] | None]:
    """:func:`transition_arrays`'s arrays and the state valuations the archive holds,
    by variable (:func:`unpack_valuations`; None where the layout is not the one read
    here, or the model was built without them)."""
    arrays, packed, _ = read_export_parts(model, where)
    return arrays, packed


def read_export_parts(model: Any, where: str, origins: bool = False,
                 labels: dict[str, np.ndarray] | None = None,
                 ) -> tuple[tuple[np.ndarray, ...], dict[str, np.ndarray] | None,
                            tuple[np.ndarray, list[str]] | None]:
    """:func:`read_export`'s arrays and valuations, and each choice's label as the
    archive holds it (:func:`_choice_actions`; its origin instead when ``origins``);
    given ``labels``, the state labels the archive holds put there (:func:`_state_labels`)."""
    try:
        choices, branches, targets, probabilities, packed, actions = _export(model, where,
                                                                             origins, labels)
    except OSError as exc:
        raise WorldError(
            f"{where}: cannot write Storm's export to a temporary folder: {exc.strerror or exc}"
        ) from None
    n, m, b = len(choices) - 1, len(branches) - 1, len(targets)
    ok = (
        choices[0] == 0 and choices[-1] == m and branches[0] == 0 and branches[-1] == b
        and bool((choices[1:] > choices[:-1]).all())  # rising: no array of differences
        and bool((branches[1:] > branches[:-1]).all())
        and (b == 0 or (targets.min() >= 0 and targets.max() < n))
    )
    if not ok:
        raise WorldError(f"{where}: Storm's UMB export is inconsistent; not supported")
    positive = probabilities != 0.0
    if not positive.all():  # a branch of probability 0 is no successor
        kept = np.add.reduceat(positive.astype(np.int64), branches[:-1])
        branches = np.concatenate(([0], np.cumsum(kept)))
        targets, probabilities = targets[positive], probabilities[positive]
    return (choices, branches, targets, probabilities), packed, actions


def _export(model: Any, where: str, origins: bool = False,
            labels: dict[str, np.ndarray] | None = None) -> tuple[Any, ...]:
    """Write ``model`` as an uncompressed UMB archive to a temporary folder and read its
    four transition arrays straight from the file, its state valuations
    (:func:`unpack_valuations`) and its choices' labels (:func:`_choice_actions`; with
    ``origins``, the identifiers of their choice origins, which Storm then writes as
    the choices' actions, :mod:`mitld_lp.worlds.prism_origins`)."""
    import stormpy.io  # pyright: ignore[reportMissingImports]

    n, m = model.nr_states, model.nr_choices
    options = stormpy.io.UmbExportOptions()
    options.compression = stormpy.io.CompressionMode.NO_COMPRESSION
    if origins:
        options.allow_choice_origins_as_actions = True
    unsupported = f"{where}: Storm's UMB export is not as expected; this stormpy is not supported"
    with tempfile.TemporaryDirectory(prefix="mitld-prism-") as folder:
        path = os.path.join(folder, "model.umb")
        with storm_quiet():
            stormpy.io.export_to_umb(model, path, options=options)
        members = archive_members(path)  # from the tar headers: prism_archive
        index = members.get("index.json")
        meta = json.loads(read_member(path, index)) if index else {}
        system = meta.get("transition-system", {})
        b = system.get("#branches", -1)
        if (system.get("#states"), system.get("#choices")) != (n, m) or system.get(
            "branch-probability-type"
        ) != {"size": 64, "type": "double"}:
            raise WorldError(unsupported)

        def read(name: str, dtype: str, count: int) -> np.ndarray:
            member = members.get(name)
            if member is None or member.size != count * 8:
                raise WorldError(f"{unsupported} ({name})")
            return np.fromfile(path, dtype=dtype, count=count, offset=member.offset_data)

        # a DTMC's archive has no state-to-choices (a choice per state, in order)
        one_each = n == m and "state-to-choices.bin" not in members
        if labels is not None:
            labels.update(_state_labels(path, members, meta, n))
        records = members.get(VALUATIONS_BIN)
        packed = None if records is None else unpack_valuations(
            meta.get("valuations", {}).get("states", {}), n, records.size,
            lambda: np.fromfile(path, dtype=np.uint8, count=records.size,
                                offset=records.offset_data))
        # Storm's unsigned 64-bit offsets and targets read as int64 at once (no copy):
        # one of 2^63 or more would read negative, which read_export_parts's checks refuse
        return (
            np.arange(n + 1, dtype=np.int64) if one_each else
            read("state-to-choices.bin", "<i8", n + 1),
            read("choice-to-branches.bin", "<i8", m + 1),
            read("branch-to-target.bin", "<i8", b),
            read("branch-to-probability.bin", "<f8", b),
            packed,
            _choice_actions(path, members, m),
        )


def _choice_actions(path: str, members: Mapping[str, Any], m: int,
                    ) -> tuple[np.ndarray, list[str]] | None:
    """Each choice's label from the UMB archive at ``path`` (Storm writes a model's
    choice labels there as its actions): ``(index, strings)``, ``m`` indices into the
    distinct strings, ``""`` for a choice without a label; None where the archive has
    none or another layout (the caller then asks Storm label by label)."""
    values = members.get(ACTIONS + "values.bin")
    mapping = members.get(ACTIONS + "string-mapping.bin")
    text = members.get(ACTIONS + "strings.bin")
    if values is None or mapping is None or text is None or values.size != 4 * m \
            or mapping.size % 8 or mapping.size < 16:
        return None
    ends = np.fromfile(path, dtype="<u8", count=mapping.size // 8, offset=mapping.offset_data)
    raw = np.fromfile(path, dtype=np.uint8, count=text.size, offset=text.offset_data).tobytes()
    if ends[0] != 0 or ends[-1] != len(raw) or np.any(np.diff(ends.astype(np.int64)) < 0):
        return None
    strings = [raw[int(a):int(z)].decode() for a, z in zip(ends[:-1], ends[1:], strict=True)]
    index = np.fromfile(path, dtype="<u4", count=m, offset=values.offset_data)
    if m and int(index.max()) >= len(strings):
        return None
    return index, strings


def _state_labels(path: str, members: Mapping[str, Any], meta: Mapping[str, Any], n: int,
                  ) -> dict[str, np.ndarray]:
    """Each state label the UMB archive at ``path`` holds, by name (its ``alias``): ``n``
    flags from its bit vector (``annotations/aps/<key>/states/values.bin``, bit ``i`` of
    byte ``i // 8`` least significant first), read in one call where Storm's own bit
    vector is read from its text (:func:`~mitld_lp.worlds.prism_labels.indices`); the
    labels of another type or layout left out (:func:`label_states` asks Storm)."""
    out: dict[str, np.ndarray] = {}
    aps = meta.get("annotations", {}).get("aps", {})
    if not isinstance(aps, dict):
        return out
    for key, about in aps.items():
        if not isinstance(about, dict) or about.get("type") != {"size": 1, "type": "bool"} \
                or about.get("applies-to") != ["states"]:
            continue
        member = members.get(f"{APS}{key}/states/values.bin")
        if member is None or member.size < (n + 7) // 8:
            continue
        raw = np.fromfile(path, dtype=np.uint8, count=(n + 7) // 8, offset=member.offset_data)
        out[str(about.get("alias", key))] = np.unpackbits(raw, bitorder="little")[:n].view(bool)
    return out


def label_states(model: Any, label: str, archive: Mapping[str, np.ndarray] | None = None,
                 ) -> np.ndarray:
    """The states of Storm's state label ``label``: from the archive's flags
    (:func:`_state_labels`) where it holds them and they agree with Storm's bit vector
    (:func:`~mitld_lp.worlds.prism_labels.agrees`), else from that bit vector."""
    bits = model.labeling.get_states(label)
    flags = None if archive is None else archive.get(label)
    if flags is not None and agrees(flags, bits):
        return np.flatnonzero(flags)
    return indices(bits)


APS = "annotations/aps/"
"""The UMB archive's folder of the state labels (atomic propositions)."""

VALUATIONS_BIN = "valuations/states/valuations.bin"
"""The UMB archive's state valuations: one record of bit fields per state."""

ACTIONS = "actions/choices/"
"""The UMB archive's folder of the choices' actions (Storm's choice labels)."""


def unpack_valuations(layout: Mapping[str, Any], n: int, size: int,
            read: Callable[[], np.ndarray]) -> dict[str, np.ndarray] | None:
    """Each variable's values over the ``n`` states from the UMB archive's records
    (``read()`` gives the file's ``size`` bytes): per state, one record of the
    variables' fields in ``layout``'s order, least significant bit first, a Boolean in
    one bit, an integer as an unsigned field plus its ``offset`` (its range's lower
    bound), ``padding`` bits between.  None where the layout is not that one (several
    classes of records, another type, a field wider than 56 bits, records that do not
    fill whole bytes or the file): the caller then asks Storm variable by variable."""
    classes = layout.get("classes")
    if n == 0 or not isinstance(classes, list) or len(classes) != 1:
        return None
    fields: list[tuple[str, int, int, int]] = []  # name, bit offset, width, value offset
    at = 0
    for var in classes[0].get("variables", ()):
        if "padding" in var:
            at += int(var["padding"])
            continue
        kind, width = var.get("type", {}).get("type"), int(var.get("type", {}).get("size", 0))
        if kind not in ("bool", "uint") or not 0 < width <= 56 or (kind == "bool"
                                                                   and width != 1):
            return None
        fields.append((str(var["name"]), at, width, int(var.get("offset", 0))))
        at += width
    if at % 8 or at == 0 or size != n * (at // 8):
        return None
    width_bytes = at // 8
    raw = np.zeros((n, width_bytes + 8), dtype=np.uint8)  # 8 spare bytes: any field's word
    raw[:, :width_bytes] = read().reshape(n, width_bytes)
    out = {}
    for name, bit, width, offset in fields:
        word = np.ascontiguousarray(raw[:, bit // 8 : bit // 8 + 8]).view("<u8").reshape(-1)
        value = (word >> np.uint64(bit % 8)) & np.uint64((1 << width) - 1)
        out[name] = value.astype(np.int64) + offset
    return out


class Valuations(Sequence[State]):
    """The states as the rows of one integer array (a column per variable, in
    :attr:`Tables.variables` order); state ``i`` becomes the tuple of its values (a
    ``bool`` for a Boolean variable, else an ``int``) when asked for.  A million tuples
    would cost a hundred megabytes and seconds to make, copy back from the exploring
    child and index, and the product reads none of them."""

    def __init__(self, values: np.ndarray, booleans: tuple[int, ...]) -> None:
        self.values = values  # (n, k): the smallest integer type that holds them all
        self.booleans = booleans  # the columns of Boolean variables

    def __len__(self) -> int:
        return int(self.values.shape[0])

    def _tuples(self, block: np.ndarray) -> list[State]:
        rows = block.tolist()
        for row in rows if self.booleans else ():
            for j in self.booleans:
                row[j] = bool(row[j])
        return [tuple(row) for row in rows]

    def rows(self, indices: np.ndarray) -> list[State]:
        """The states at ``indices``, in one call."""
        return self._tuples(self.values[indices])

    @overload
    def __getitem__(self, i: int) -> State: ...
    @overload
    def __getitem__(self, i: slice) -> tuple[State, ...]: ...
    def __getitem__(self, i: int | slice) -> State | tuple[State, ...]:
        if isinstance(i, slice):
            return tuple(self._tuples(self.values[i]))
        return self._tuples(self.values[i][None, :])[0]

    def __iter__(self) -> Iterator[State]:
        for lo in range(0, len(self), 1 << 16):
            yield from self._tuples(self.values[lo : lo + (1 << 16)])

    def __eq__(self, other: object) -> bool:  # as the tuple of the states would compare
        if isinstance(other, Valuations | tuple | list):
            return len(self) == len(other) and all(a == b for a, b in zip(self, other,
                                                                         strict=True))
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"Valuations(<{len(self)} states>)"


def _narrow(values: np.ndarray) -> np.ndarray:
    """``values`` in the smallest signed integer type that holds them."""
    if values.size == 0:
        return values.astype(np.int8)
    lo, hi = int(values.min()), int(values.max())
    for kind in (np.int8, np.int16, np.int32):
        info = np.iinfo(kind)
        if info.min <= lo and hi <= info.max:
            return values.astype(kind)
    return values


def valuations_of(model: Any, hidden: frozenset[str] = frozenset(),
                packed: Mapping[str, np.ndarray] | None = None,
                ) -> tuple[tuple[str, ...], Valuations]:
    """The variables (in Storm's order, but ``hidden``) and each state's values: from
    ``packed`` (the UMB archive's, :func:`unpack_valuations`) where it has the variable,
    else one call to Storm per variable."""
    n = model.nr_states
    valuations = model.state_valuations
    order = tuple(json.loads(str(valuations.to_json(0))) or ()) if n else ()  # null: none
    order = tuple(name for name in order  # Storm's own bit (see _build), and ``hidden``
                  if name != OUT_OF_BOUNDS_BIT and name not in hidden)
    by_name = {v.name: v for v in valuations.get_all_variables()}
    values = np.zeros((n, len(order)), dtype=np.int64)
    booleans = []
    for j, name in enumerate(order):
        var = by_name[name]
        if packed is not None and name in packed:  # the archive's, read as one array
            values[:, j] = packed[name]
            if var.has_boolean_type():
                booleans.append(j)
        elif var.has_boolean_type():  # a bit vector: the states where it is true
            values[indices(valuations.get_boolean_values(var)), j] = 1
            booleans.append(j)
        else:  # PRISM state variables are booleans and bounded integers
            values[:, j] = np.asarray(valuations.get_int64_values(var), dtype=np.int64)
    return order, Valuations(_narrow(values), tuple(booleans))


def read_model(
    model: Any,
    where: str,
    chosen: frozenset[str],
    events: frozenset[str],
    action_names: Mapping[str, str],
    origin: Callable[[int], str],
    decided: str | None = None,
    *,
    silent: str | None = None,
    hidden: frozenset[str] = frozenset(),
    valuations: tuple[tuple[str, ...], Valuations] | None = None,
    named: Callable[[Any, tuple[np.ndarray, list[str]] | None],
                    tuple[list[str], np.ndarray]] | None = None,
    shared: bool = True,
    late: bool = False,
) -> Tables:
    """Copy Storm's ``model`` into :class:`Tables`.

    ``action_names`` maps Storm's choice labels to action names (a command without an
    action was given a fresh one before the build); a choice without a label is the
    deadlock self-loop.  ``origin(choice)`` names the commands a choice comes from, used
    only where two choices of a state would have the same name.  ``decided``: Storm's
    label of the states it did not expand (terminal states); their self-loop is named
    :data:`DECIDED_ACTION`.  ``silent``: the name of a choice without a label at a state
    Storm did not label ``"deadlock"`` (a JANI edge without an action; None: every choice
    without a label is the deadlock self-loop, as in a PRISM build where every command
    has an action).  ``hidden``: variables of Storm's valuations that are not the state's
    (JANI's transient variables).  ``valuations``: the variables and the states, when
    ``model`` was built without its valuations (:mod:`mitld_lp.worlds.prism_valuations`).
    ``named``: where ``model`` has Storm's choice origins in place of its choice labels,
    what names the choices from them (``named(model, origins)``, the origins the archive
    holds: :class:`mitld_lp.worlds.prism_origins.OriginNames`), as the labels would.
    ``shared``: whether two choices of one state may have one name (False: the program
    allows none, :func:`mitld_lp.worlds.prism_origins.may_share_names`; not looked for).
    ``late``: a choice without a label at a state Storm did not label ``deadlock`` (and
    not decided), or of a label twice in its state, is named when first read: its id is
    ``LATE + c`` (:mod:`mitld_lp.worlds.prism_names`); ``model`` may then have no choice
    labels (every choice but those self-loops is late).
    Raises :class:`WorldError` for an update that reached
    Storm's :data:`OUT_OF_BOUNDS` state (out of a variable's range), a state where only
    events are enabled, an event with two enabled commands in a state, a negative probability,
    or a distribution whose probabilities do not sum to 1 within PRISM's tolerance
    (:data:`mitld_lp.worlds.prism_program.SUM_TOLERANCE`).  A distribution within that
    tolerance but not within the game's own
    (:data:`~mitld_lp.worlds.successors.PROBABILITY_TOLERANCE`) is divided by its sum,
    and counted in :attr:`Tables.normalised`: the one place PRISM's rule is applied.
    """
    archive: dict[str, np.ndarray] = {}  # the state labels the export holds
    (choices, branches, targets, probabilities), packed, actions = read_export_parts(
        model, where, origins=named is not None, labels=archive)
    variables, states = (valuations if valuations is not None else
                         valuations_of(model, hidden, packed))
    del packed
    n, m = len(states), len(branches) - 1

    def show(s: int) -> str:
        return "[" + " & ".join(f"{k}={v}" for k, v in zip(variables, states[s], strict=True)) + "]"

    state_of = np.repeat(np.arange(n, dtype=np.int64), np.diff(choices))  # each >= 1
    if named is not None:  # every choice named by the commands it comes from
        label_names, label_of = named(model, actions)
    elif not model.has_choice_labeling():  # built without: every choice named late
        if not late:
            raise AssertionError("a model without choice labels is read with late names")
        label_names, label_of = [], np.full(m, -1, dtype=np.int64)
    else:
        label_names = sorted(model.choice_labeling.get_labels())
        label_of = choice_labels(model, label_names, m, actions)  # -1: none, the deadlock loop
    # each choice's name as an index into ``table`` (no object per choice)
    table = [action_names.get(label, label) for label in label_names] + [DEADLOCK_ACTION]
    code = np.where(label_of < 0, len(table) - 1, label_of)  # -1: the deadlock self-loop
    dead = len(table) - 1
    if silent is not None and np.any(label_of < 0):  # or a silent edge, where no deadlock
        stuck = np.zeros(n, dtype=bool)
        if "deadlock" in model.labeling.get_labels():
            stuck[label_states(model, "deadlock", archive)] = True
        table.append(silent)
        code[(label_of < 0) & ~stuck[state_of]] = len(table) - 1

    n_decided = 0
    if decided is not None:
        stopped = np.zeros(n, dtype=bool)
        stopped[label_states(model, decided, archive)] = True
        alone = stopped & (np.diff(choices) == 1)  # Storm's one self-loop, unlabelled
        unlabelled = alone[state_of] & (label_of == -1)
        table.append(DECIDED_ACTION)
        code[unlabelled] = len(table) - 1
        n_decided = int(np.count_nonzero(unlabelled))

    if OUT_OF_BOUNDS in model.labeling.get_labels():  # Storm built without its checks
        outside = np.zeros(n, dtype=bool)
        outside[label_states(model, OUT_OF_BOUNDS, archive)] = True
        choice_of = np.repeat(np.arange(m), np.diff(branches))  # per branch
        c = int(choice_of[np.flatnonzero(outside[targets] & ~outside[state_of[choice_of]])[0]])
        raise WorldError(f"{where}: at state {show(int(state_of[c]))}, action "
                         f"{table[int(code[c])]!r}: an update gives a variable a value "
                         "outside its range")

    lengths = np.diff(branches)
    bad, total, branch_row = checked_rows(lengths, probabilities, SUM_TOLERANCE)
    if bad.size:
        c = int(bad[0])
        row = probabilities[int(branches[c]):int(branches[c + 1])]
        at = f"{where}: at state {show(int(state_of[c]))}, action {table[int(code[c])]!r}"
        negative = row[row < 0.0]
        if negative.size:
            raise WorldError(f"{at}: a probability is negative ({float(negative[0])!r})")
        raise WorldError(f"{at}: probabilities sum to {show_sum(float(row.sum()))}, not 1")
    probabilities, rows, largest = normalise_rows(lengths, probabilities, (total, branch_row))
    del total, branch_row
    normalised = None if rows == 0 else Normalisation(where, rows, largest, SUM_TOLERANCE)
    if normalised is not None:
        log.info("%s", normalised)

    effects: dict[str, np.ndarray] = {}
    robot = np.ones(m, dtype=bool)
    for event in sorted(events):
        mine = np.flatnonzero(np.isin(code, [k for k, a in enumerate(table) if a == event]))
        robot[mine] = False
        at = state_of[mine]
        twice = np.flatnonzero(np.bincount(at, minlength=n) > 1)
        if twice.size:
            raise WorldError(
                f"{where}: event {event!r} has two enabled commands at state "
                f"{show(int(twice[0]))}; an event's effect must be one command per state"
            )
        effect = np.full(n, -1, dtype=np.int64)
        effect[at] = mine
        effects[event] = effect
    stuck = np.flatnonzero(np.bincount(state_of[robot], minlength=n) == 0) if events else ()
    if len(stuck):  # (without events every choice is the robot's, and every state has one)
        raise WorldError(
            f"{where}: at state {show(int(stuck[0]))} only event commands are enabled; the "
            "robot needs an action there (e.g. [wait] true -> true;)"
        )

    # Two robot choices of one state with one name: told apart by their commands (when
    # first read if ``late``: two of one label are late choices then).
    clash = np.zeros(0, dtype=np.int64)
    if shared:
        look = robot & (label_of >= 0) if late else robot
        key = state_of * (len(label_names) + 1) + label_of + 1
        twice = repeated(key[look])
        if twice.size:
            clash = np.flatnonzero(look & np.isin(key, twice))
    for c in [] if late else clash.tolist():
        table.append(f"{table[int(code[c])]}@{origin(c)}")
        code[c] = len(table) - 1
    for s in [] if late else np.unique(state_of[clash]).tolist():
        mine = slice(choices[s], choices[s + 1])
        row = [table[k] for k in code[mine][robot[mine]].tolist()]
        for name in sorted({x for x in row if row.count(x) > 1}):
            raise WorldError(f"{where}: two choices named {name!r} at state {show(s)}")
    # one index per distinct name; -1 for an event's choice
    distinct: dict[str, int] = {}
    remap = np.array([distinct.setdefault(a, len(distinct)) for a in table], dtype=np.int32)
    action_index = remap[code]
    action_index[~robot] = -1
    if late:  # an unlabelled command's choice (no label, not Storm's self-loop), a clash
        loop = np.zeros(n, dtype=bool)
        if "deadlock" in model.labeling.get_labels():
            loop[label_states(model, "deadlock", archive)] = True
        mine = (label_of < 0) & (code == dead) & ~loop[state_of]
        mine[clash] = True
        action_index[mine] = LATE + np.flatnonzero(mine)

    initial = list(model.initial_states)
    if len(initial) != 1:
        raise WorldError(
            f"{where}: the model has {len(initial)} initial states; a game needs exactly one"
        )
    label_sets, label_index = state_labels(model, chosen, archive)
    return Tables(
        variables=variables,
        states=states,
        initial=int(initial[0]),
        label_sets=label_sets,
        label_index=label_index,
        choices=choices,
        branches=branches,
        targets=targets,
        probabilities=probabilities,
        action_names=tuple(distinct),
        action_index=action_index,
        effects=effects,
        decided=n_decided,
        normalised=normalised,
        checked=True,  # every row: checked_rows above, and normalise_rows
    )

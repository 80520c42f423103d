"""Storm's state and choice labelling read into numpy arrays (for
:func:`mitld_lp.worlds.prism_tables.read_model`): a bit vector's set positions in one
pass over its text, each state's set of labels as an index into the distinct sets, each
choice's label, and the keys found twice (two choices of one name in a state).  No sort
of a state-sized array where a count per code does (16 labels or fewer)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["indices", "agrees", "state_labels", "flag_labels", "label_sets", "choice_labels",
           "repeated"]


def indices(bits: Any) -> np.ndarray:
    """The set positions of one of Storm's bit vectors: from its text (its size, then
    its 64-bit words in decimal, the first position the word's most significant bit),
    read in one numpy pass, checked against its count of set bits; else (another text)
    by iterating over it, a Python int per position."""
    try:
        size, *words = bits.store_as_string().split()
        n = int(size)
        if len(words) == (n + 63) // 64:
            packed = np.array(words, dtype=np.uint64).astype(">u8").view(np.uint8)
            found = np.flatnonzero(np.unpackbits(packed)[:n])
            if found.size == bits.get_number_of_set_bits():
                return found.astype(np.int64, copy=False)
    except (AttributeError, ValueError, OverflowError):
        pass
    return np.fromiter(bits, dtype=np.int64)


def agrees(flags: np.ndarray, bits: Any, samples: int = 32) -> bool:
    """Whether the flags read from Storm's UMB export are its bit vector ``bits``: as
    many set, and Storm's own bit set at up to ``samples`` of the flagged positions
    spread over them (the first and the last among them), each with as many set
    before it (a bit order read wrong moves them)."""
    found = np.flatnonzero(flags)
    if flags.size != bits.size() or found.size != bits.get_number_of_set_bits():
        return False
    if found.size == 0:
        return True
    spread = np.linspace(0, found.size - 1, min(samples, found.size)).astype(np.int64)
    picks = spread[np.diff(spread, prepend=-1) != 0]  # rising: its distinct values in one pass
    return all(bits.get(int(found[j])) and bits.get_number_of_set_bits_before_index(
        int(found[j])) == int(j) for j in picks.tolist())


def state_labels(model: Any, chosen: frozenset[str],
                 archive: Mapping[str, np.ndarray] | None = None,
                 ) -> tuple[tuple[frozenset[str], ...], np.ndarray]:
    """The distinct sets of the ``chosen`` labels a state satisfies, and per state the
    index of its set.  ``archive``: each label's ``n`` flags as Storm's UMB export holds
    them, used where they count the states Storm's bit vector counts."""
    n = model.nr_states
    names = sorted(chosen)
    if not names:
        return (frozenset(),), np.zeros(n, dtype=np.int32)
    packed = np.zeros((n, (len(names) + 7) // 8), dtype=np.uint8)
    for k, label in enumerate(names):
        bits = model.labeling.get_states(label)
        flags = None if archive is None else archive.get(label)
        if flags is not None and agrees(flags, bits):
            packed[:, k // 8] |= flags.view(np.uint8) * np.uint8(128 >> (k % 8))
        else:
            packed[indices(bits), k // 8] |= np.uint8(128 >> (k % 8))
    return label_sets(packed, names)


def flag_labels(flags: np.ndarray, names: list[str]) -> tuple[tuple[frozenset[str], ...],
                                                               np.ndarray]:
    """:func:`state_labels` of ``n x len(names)`` flags (the own explorer's, each
    state's truth of each label, ``names`` sorted): nothing to check against Storm's."""
    if not names:
        return (frozenset(),), np.zeros(flags.shape[0], dtype=np.int32)
    packed = np.packbits(flags, axis=1)  # label k at bit 128 >> (k % 8) of byte k // 8
    return label_sets(packed, names)


def label_sets(packed: np.ndarray, names: list[str]) -> tuple[tuple[frozenset[str], ...],
                                                               np.ndarray]:
    """The distinct rows of ``packed`` (label ``k`` of ``names`` at bit ``128 >> (k % 8)``
    of byte ``k // 8``) as sets of names, and each row's index among them."""
    n = packed.shape[0]
    if packed.shape[1] <= 2:  # at most 16 labels: a count per code, no sort
        rows, inverse = _small_unique(packed)
    elif packed.shape[1] <= 8:  # a state's labels as one big-endian integer: a 1-d unique
        wide = np.zeros((n, 8), dtype=np.uint8)
        wide[:, : packed.shape[1]] = packed
        codes, inverse = np.unique(wide.view(">u8").reshape(-1), return_inverse=True)
        rows = codes.astype(">u8").view(np.uint8).reshape(-1, 8)[:, : packed.shape[1]]
    else:
        rows, inverse = np.unique(packed, axis=0, return_inverse=True)
    bits = np.unpackbits(rows, axis=1)[:, : len(names)]
    sets = tuple(frozenset(np.asarray(names)[row.astype(bool)].tolist()) for row in bits)
    return sets, np.asarray(inverse).reshape(-1).astype(np.int32)


def repeated(keys: np.ndarray) -> np.ndarray:
    """The values found more than once in ``keys``, sorted.  A stable sort: the keys come
    grouped by state (a run per state), which it merges in about one pass."""
    ordered = np.sort(keys, kind="stable")
    same = ordered[1:] == ordered[:-1]
    return np.unique(ordered[1:][same])


def _small_unique(packed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(packed, axis=0, return_inverse=True)`` of rows of one or two bytes, in
    one pass: each row read as a big-endian integer below ``2^16`` (the rows' order), the
    codes present found by a count per code, each row's index by a running count."""
    width = packed.shape[1]
    small = np.zeros(packed.shape[0], dtype=np.intp)
    for j in range(width):
        small = (small << 8) | packed[:, j]
    present = np.bincount(small, minlength=1 << (8 * width)) > 0
    codes = np.flatnonzero(present)
    inverse = (np.cumsum(present) - 1)[small]
    rows = np.stack([(codes >> (8 * (width - 1 - j))) & 255 for j in range(width)],
                    axis=1).astype(np.uint8)
    return rows, inverse


def choice_labels(model: Any, names: list[str], m: int,
              actions: tuple[np.ndarray, list[str]] | None) -> np.ndarray:
    """Each of the ``m`` choices' label as an index into ``names`` (Storm's choice
    labels, sorted), -1 for none: from the archive's actions in one pass where each is
    one of ``names`` or empty and each label counts the choices Storm's bit vector of it
    has (so no choice has two), else from those bit vectors (a pass over the choices per
    label: 1.3 s of CPU for 37 labels on QVBS consensus 6-2's 5.0M choices)."""
    if actions is not None:
        index, strings = actions
        position = {name: k for k, name in enumerate(names)}
        position[""] = -1
        if all(x in position for x in strings) and len(set(strings)) == len(strings):
            label_of = np.array([position[x] for x in strings], dtype=np.int64)[index]
            counts = np.bincount(label_of + 1, minlength=len(names) + 1)[1:]
            if all(int(counts[k]) == model.choice_labeling.get_choices(name)
                   .get_number_of_set_bits() for k, name in enumerate(names)):
                return label_of
    label_of = np.full(m, -1, dtype=np.int64)
    for k, label in enumerate(names):
        label_of[indices(model.choice_labeling.get_choices(label))] = k
    return label_of


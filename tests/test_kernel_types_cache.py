"""The kernel loader's type key (mitld_lp.util.kernel_types.type_key) looked up by an
array's dtype, dimensions and flags: the same key as the one made from the array each
time (array_part), and numba's own type's parts (numba.typeof: dtype, dimensions,
layout, read-only), for arrays that differ in one of them at a time, the same
array read before and after its flags change, and every scalar kind."""

from __future__ import annotations

import numpy as np
import pytest

from mitld_lp.util import kernel_types
from mitld_lp.util.kernel_types import array_part, sample_args, type_key


def _arrays() -> list[np.ndarray]:
    out = []
    for dt in (np.float64, np.int32, np.int64, np.uint8, np.bool_, np.complex128):
        c = np.zeros((4, 6), dtype=dt)
        out += [c, c[0], c[:, 1], np.asfortranarray(c), c[:, ::2], c.T, c[:0],
                np.zeros(0, dtype=dt), np.zeros((), dtype=dt)]
        frozen = c.copy()
        frozen.setflags(write=False)
        out += [frozen, frozen[:, ::2]]
    buf = np.frombuffer(bytearray(8 * 6 + 1), dtype=np.uint8)[1:49]
    out.append(buf.view(np.float64))  # unaligned
    out.append(np.zeros(3, dtype=">f8"))  # not native: no key
    out.append(np.zeros(3, dtype=[("a", "<f8")]))  # structured: no key
    out.append(np.zeros(3, dtype=object))
    return out


def test_looked_up_key_is_the_made_one_for_every_array() -> None:
    arrays = _arrays()
    for _ in range(2):  # the first round fills the table, the second reads it
        for a in arrays:
            assert type_key((a,)) == (None if array_part(a) is None else (array_part(a),))
    keys = {type_key((a,)) for a in arrays}
    assert len(kernel_types._PARTS) >= len(keys) - 1  # one entry a kind of array


def test_the_same_array_read_after_its_flags_change() -> None:
    a = np.zeros(5)
    before = type_key((a,))
    a.setflags(write=False)
    after = type_key((a,))
    assert before[0][4] is False and after[0][4] is True
    assert after == (array_part(a),)


def test_scalars_and_refusals() -> None:
    assert type_key((1, 2.0, True, np.bool_(False), np.int32(3), np.float32(1.0))) == (
        ("int",), ("float",), ("bool",), (np.bool_.__name__,), ("scalar", "<i4"),
        ("scalar", "<f4"))
    assert type_key((2 ** 63,)) is None  # past int64
    assert type_key((-(2 ** 63),)) == (("int",),)
    assert type_key(("text",)) is None
    assert type_key((np.zeros(2).view(np.recarray),)) is None  # a subclass: numba's
    assert type_key((np.complex128(1),)) is None


def test_key_parts_are_numbas_types() -> None:
    numba = pytest.importorskip("numba")
    for a in _arrays():
        part = array_part(a)
        if part is None:
            continue
        t = numba.typeof(a)
        # (the key's aligned flag is its own: numba's typeof types every array aligned)
        assert (t.ndim, t.layout, not t.mutable) == part[2:5], (a.dtype, part)
        assert np.dtype(str(t.dtype) if str(t.dtype) != "bool" else np.bool_) == \
            np.dtype(part[1])


def test_sample_args_give_their_key_back() -> None:
    for a in _arrays():
        key = type_key((a, 1, 0.5))
        if key is not None and a.ndim:
            assert type_key(sample_args(key)) == key

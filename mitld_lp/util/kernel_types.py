"""numba's type of a kernel's arguments, computed with NumPy alone: the key by which
:mod:`mitld_lp.util.kernel_loader` names a kernel's cache file of one signature, and
the inverse, arguments of a given key (:func:`sample_args`: what ``mitld-lp warm``
compiles each signature for, never running the kernel on them)."""

from __future__ import annotations

import numpy as np

__all__ = ["array_part", "sample_args", "type_key"]


def type_key(args: tuple) -> tuple | None:
    """numba's type of each argument as NumPy gives it (``numba.typeof``'s inputs: an
    array's dtype, dimensions, layout C / F / A, read-only and aligned flags; a Python
    bool, int (int64) or float; a NumPy scalar's dtype), or None for anything else
    (numba's dispatcher then decides).  An array's part is looked up by its dtype,
    dimensions and the four flags it reads (:func:`_array_part`): a kernel call's key
    is made once a solve's many calls (4 us an argument, built, against 1 looked up)."""
    out: list[tuple] = []
    for a in args:
        t = type(a)
        if t is np.ndarray:  # (_array_part's lookup, inline: a call an array saved)
            part = _PARTS.get((a.dtype, a.ndim, a.flags.num & _READ_FLAGS), _MISSING)
            if part is _MISSING:
                part = _array_part(a)
        elif t is int:
            part = _INT if -(2 ** 63) <= a < 2 ** 63 else None
        else:
            part = _SCALARS.get(t)
            if part is None and isinstance(a, np.generic) and a.dtype.kind in "iuf" \
                    and a.dtype.isnative:
                part = ("scalar", a.dtype.str)
        if part is None:
            return None
        out.append(part)
    return tuple(out)


_INT = ("int",)
# a Python bool or float, NumPy's bool (its type's name: "bool" in NumPy 2): their parts
_SCALARS: dict[type, tuple] = {bool: ("bool",), np.bool_: (np.bool_.__name__,),
                              float: ("float",)}


# NumPy's flag bits (its C API's NPY_ARRAY_*, the value of ``ndarray.flags.num``) of
# what an array's part reads: C and F contiguous, aligned, writeable
_READ_FLAGS = 0x0001 | 0x0002 | 0x0100 | 0x0400
_PARTS: dict[tuple, tuple | None] = {}  # (dtype, ndim, read flags) -> the array's part
_MISSING = object()


def _array_part(a: np.ndarray) -> tuple | None:
    """:func:`array_part` of ``a``, kept by what it is made of (its dtype, dimensions
    and :data:`_READ_FLAGS`): the same tuple for the same inputs."""
    k = (a.dtype, a.ndim, a.flags.num & _READ_FLAGS)
    part = _PARTS.get(k, _MISSING)
    if part is _MISSING:
        part = array_part(a)
        if len(_PARTS) < 4096:  # a few dozen in a process; never grown without end
            _PARTS[k] = part
    return part  # type: ignore[return-value]


def array_part(a: np.ndarray) -> tuple | None:
    """An array's part of :func:`type_key`, made from its dtype and flags: its dtype's
    string, dimensions, layout (C, F, else A), read-only and aligned flags; None for a
    dtype numba's kernels here are not typed for (structured, non-native, object)."""
    dt = a.dtype
    if dt.kind not in "biufc" or not dt.isnative or dt.fields is not None:
        return None
    f = a.flags
    layout = "C" if f.c_contiguous else "F" if f.f_contiguous else "A"
    return ("array", dt.str, a.ndim, layout, not f.writeable, f.aligned)


def sample_args(key: tuple) -> tuple:
    """Arguments whose :func:`type_key` is ``key`` (tiny arrays of its dtypes, dimensions,
    layouts and flags; zeros and False): what a kernel is compiled for without being
    run.  ValueError for a key :func:`type_key` never gives."""
    out = []
    for part in key:
        kind = part[0]
        if kind == "array":
            out.append(_sample_array(*part[1:]))
        elif kind in ("bool", "bool_") and len(part) == 1:
            out.append(False)
        elif kind == "int" and len(part) == 1:
            out.append(0)
        elif kind == "float" and len(part) == 1:
            out.append(0.0)
        elif kind == "scalar" and len(part) == 2:
            out.append(np.dtype(part[1]).type(0))
        else:
            raise ValueError(f"not an argument type of a kernel: {part!r}")
    args = tuple(out)
    if type_key(args) != tuple(key):
        raise ValueError(f"no arguments of the type {key!r}")
    return args


def _sample_array(dtype: str, ndim: int, layout: str, readonly: bool,
                  aligned: bool) -> np.ndarray:
    dt = np.dtype(dtype)
    if not aligned:  # a view one byte into a buffer of the dtype's size and more
        a = np.frombuffer(bytearray(dt.itemsize * 2 ** ndim * 2 + 1), dtype=np.uint8)
        a = a[1:1 + dt.itemsize * 2 ** ndim].view(dt).reshape((2,) * ndim)
    else:
        a = np.zeros((2,) * ndim, dtype=dt)
    if layout == "F":
        a = np.asfortranarray(a)
    elif layout == "A":
        a = np.zeros((2,) * (ndim - 1) + (4,), dtype=dt)[..., ::2] if aligned else a[..., ::-1]
    if readonly:
        a.setflags(write=False)
    return a

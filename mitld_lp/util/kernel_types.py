"""numba's type of a kernel's arguments, computed with NumPy alone: the key by which
:mod:`mitld_lp.util.kernel_loader` names a kernel's cache file of one signature, and
the inverse, arguments of a given key (:func:`sample_args`: what ``mitld-lp warm``
compiles each signature for, never running the kernel on them)."""

from __future__ import annotations

import numpy as np

__all__ = ["sample_args", "type_key"]


def type_key(args: tuple) -> tuple | None:
    """numba's type of each argument as NumPy gives it (``numba.typeof``'s inputs: an
    array's dtype, dimensions, layout C / F / A, read-only and aligned flags; a Python
    bool, int (int64) or float; a NumPy scalar's dtype), or None for anything else
    (numba's dispatcher then decides)."""
    out: list[tuple] = []
    for a in args:
        t = type(a)
        if t is np.ndarray:
            dt = a.dtype
            if dt.kind not in "biufc" or not dt.isnative or dt.fields is not None:
                return None
            f = a.flags
            layout = "C" if f.c_contiguous else "F" if f.f_contiguous else "A"
            out.append(("array", dt.str, a.ndim, layout, not f.writeable, f.aligned))
        elif t is bool or t is np.bool_:
            out.append((t.__name__,))
        elif t is int:
            if not -(2 ** 63) <= a < 2 ** 63:
                return None
            out.append(("int",))
        elif t is float:
            out.append(("float",))
        elif isinstance(a, np.generic) and a.dtype.kind in "iuf" and a.dtype.isnative:
            out.append(("scalar", a.dtype.str))
        else:
            return None
    return tuple(out)


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

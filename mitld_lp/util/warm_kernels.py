"""Every compiled kernel signature a solve may link, and their compile (``mitld-lp warm``).

numba compiles a kernel for each signature (its arguments' types) at the first call on a
machine, seconds each: before ``warm`` compiled them all, a first solve after install
paid that (QVBS zeroconf 1000-4: 23 s of solve against 0.7 s the second time, Stop 72),
and the gates that run a kernel only where it is cached
(:func:`~mitld_lp.util.kernel_loader.cached`) kept the NumPy walks until some solve had
compiled it.  :data:`SIGNATURES` lists, per kernel module and kernel, the argument types
the routes call it with (recorded by ``experiments/kernel_calls.py`` on the QVBS
instances, the issue's cases and the bus family, with every compiled gate forced on), as
:func:`encode` writes a :func:`~mitld_lp.util.kernel_types.type_key`; :func:`compile_all`
compiles each one it finds uncached, on arguments of its type that it never runs the
kernel on (:meth:`~mitld_lp.util.kernel_loader.Kernel.compile_for`), so numba's cache
and the loader's file hold the same machine code a call's miss would have written.

``tests/test_warm_signatures.py`` records the (kernel, type) pairs small solves of
several shapes call with the gates forced on and checks each is listed here, so the list
does not rot as kernels change.  Modules are imported by name, at the compile only."""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable, Iterator

import numpy as np

__all__ = ["SIGNATURES", "compile_all", "decode", "encode", "signatures"]

SIGNATURES: dict[str, dict[str, tuple[str, ...]]] = {
    "mitld_lp.product.bfs_kernels": {
        "table_levels": (
            "i8/1C int int int int i4/1C int i8/1C i8/1C i8/1C i8/1C f8/1C i8/1C i8/1C int int "
            "float bool i4/1C int int i4/1C f8/1C i4/1C i4/1C i4/1C i8/1C",
        ),
    },
    "mitld_lp.sensing.group_kernels": {
        "decided_alone": (
            "i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C np.i8 np.i8",
        ),
        "end_sums": (
            "i8/1C i8/1C i8/1C i8/1C i8/1C f8/1C i8/1C",
        ),
        "group_shifts": (
            "i8/2C i8/1C i8/1C int i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C",
        ),
        "level_hypotheses": (
            "i8/1C i8/1C int i8/1C i8/1C f8/1C i8/1C i8/1C int i8/2C i8/1C",
        ),
    },
    "mitld_lp.sensing.kernels": {
        "_bounds": (
            "i8/1C",
        ),
        "_fold": (
            "i8/1C i8/1C int int",
        ),
        "_shift": (
            "i8/1C i8/1C int",
        ),
        "dense_groups": (
            "i8/1C int",
        ),
        "gather2": (
            "i8/2C i8/1C i8/1C",
        ),
        "hypothesis_rows": (
            "i8/1C i8/1C i8/1C f8/1C i8/1C i8/1C i8/1C i8/1C i8/1C f8/1C int int i8/1C i8/1C "
            "i8/1C i8/1C i8/1C f8/1C b1/1C i8/1C i8/1C i8/1C i8/1C i8/1C f8/1C i8/1C i8/1C i8/1C "
            "i8/1C int i8/2C i8/2C np.i8 i8/2C f8/2C",
        ),
        "key_match": (
            "i8/1C i8/2C i8/1C int i8/2C",
        ),
        "key_rehash": (
            "i8/1C i8/2C int",
        ),
        "scatter_max": (
            "i8/1C i8/1C i8/1C",
        ),
        "spread": (
            "i8/1C",
        ),
        "verify": (
            "i8/1C i8/1C i8/1C i8/1C f8/1C i8/1C f8/1C",
        ),
    },
    "mitld_lp.solvers.analysis_kernels": {
        "components_reach": (
            "i4/1C i4/1C i8/1C/ro b1/2C",
        ),
        "component_levels": (
            "i4/1C i4/1C i8/1C/ro i4/1C int",
        ),
    },
    "mitld_lp.solvers.certify_kernels": {
        "bellman_rows": (
            "i8/1C i8/1C i8/1C i4/1C i4/1C f8/1C f8/1C i4/1C/ro f8/1C/ro f8/1C/ro b1/1C bool "
            "b1/1C",
        ),
        "chain_parts": (
            "i8/1C i8/1C i4/1C i4/1C f8/1C b1/1C b1/1C b1/1C",
        ),
        "chain_blocks": (
            "i4/1C i4/1C/ro",
        ),
        "cycling": (
            "i8/1C/ro i4/1C/ro i4/1C/ro i4/1C/ro b1/1C/ro b1/1C",
        ),
    },
    "mitld_lp.solvers.certify_repair_kernels": {
        "level_rounds": (
            "i8/1C/ro b1/1C i8/1C/ro i8/1C/ro i4/1C/ro i4/1C/ro f8/1C/ro f8/1C i4/1C/ro f8/1C/ro "
            "f8/1C/ro bool i4/1C/ro i4/1C/ro int b1/1C i8/1C i8/1C",
        ),
        "state_needs": (
            "i8/1C i8/1C i8/1C i4/1C i4/1C f8/1C f8/1C i4/1C/ro f8/1C/ro f8/1C/ro bool f8/1C bool",
        ),
    },
    "mitld_lp.solvers.compiled_graph": {
        "_backward": (
            "i4/1C i4/1C i8/1C/ro b1/1C b1/1C bool",
        ),
        "closed_among": (
            "i4/1C i4/1C i8/1C i8/1C b1/1C",
        ),
        "components_and_levels": (
            "i4/1C i4/1C bool b1/2C bool",
        ),
        "end_components_among": (
            "i4/1C i4/1C b1/1C i8/1C i8/1C",
        ),
        "reaching_edges": (  # reach.backward_reachable's compiled walk (int32 edges)
            "int i4/1C i4/1C b1/1C",
        ),
        "state_levels": (
            "i4/1C i4/1C i8/1C b1/2C int",
        ),
    },
    "mitld_lp.solvers.compiled_kernels": {
        "gauss_seidel": (
            "i4/1C i4/1C f8/1C i8/1C f8/1C f8/2C f8/2C i8/1C int float bool float float f8/2C "
            "f8/1C i8/1C bool bool",
        ),
    },
    "mitld_lp.solvers.greedy_kernels": {
        "dual_check": (
            "i4/1C i4/1C f8/1C i8/1C f8/1C f8/1C f8/1C i4/1C bool",
        ),
        "greedy_choices": (
            "i4/1C i4/1C f8/1C i8/1C f8/1C f8/1C bool",
        ),
    },
    "mitld_lp.solvers.horizon_kernels": {
        "distances": (
            "int i8/1C b1/1C i8/1C i8/1C i8/1C bool",
        ),
        "reach_steps": (
            "int int int i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C f8/1C i4/1C/ro f8/1C/ro f8/1C/ro "
            "f8/1C/ro f8/1C f8/1C f8/1C f8/1C bool b1/1C u1/1C i8/1C",
            "int int int i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C f8/1C i4/1C/ro f8/1C/ro f8/1C/ro "
            "f8/1C/ro f8/1C f8/1C f8/1C f8/1C bool b1/1C u2/1C i8/1C",
            "int int int i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C f8/1C i4/1C/ro f8/1C/ro f8/1C/ro "
            "f8/1C/ro f8/1C f8/1C f8/1C f8/1C bool b1/1C u4/1C i8/1C",
        ),
    },
    "mitld_lp.solvers.level_kernels": {
        "chain_flow": (
            "i8/1C i4/1C i4/1C f8/1C f8/1C/ro f8/2C",
        ),
        "chain_solve": (
            "i8/1C i4/1C i4/1C f8/1C f8/1C/ro f8/2C f8/2C",
            "i8/1C i4/1C i4/1C f8/1C f8/1C f8/2C f8/2C",  # cert-86b's Extended: its own leave
        ),
        "chain_values": (
            "i8/1C i4/1C i4/1C f8/1C f8/1C/ro f8/1C f8/1C f8/1C f8/1C",
        ),
        "single_bounds": (
            "int int i8/1C i4/1C i8/1C i8/1C i4/1C f8/1C f8/1C f8/2C f8/2C bool",
        ),
        "single_bounds_values": (
            "int int i8/1C i4/1C i8/1C i8/1C i4/1C f8/1C f8/1C f8/2C f8/2C bool i8/1C b1/2C float "
            "f8/2C i8/2C",
        ),
        "single_flow": (
            "int int i8/1C i8/1C i4/1C i8/1C i8/1C i4/1C f8/1C f8/1C/ro f8/1C f8/1C",
        ),
        "single_values": (
            "int int i8/1C i4/1C i8/1C i8/1C i4/1C f8/1C f8/1C f8/1C/ro b1/1C/ro f8/1C i8/1C "
            "f8/1C float bool",
        ),
    },
    "mitld_lp.solvers.lift_kernels": {
        "first_staying_kernel": (
            "i8/1C/ro i4/1C/ro i4/1C/ro f8/1C/ro b1/1C/ro i8/1C/ro",
        ),
        "lift_states_kernel": (
            "i8/1C/ro i4/1C/ro i4/1C/ro f8/1C/ro b1/1C/ro bool i4/1C/ro i4/1C/ro b1/1C/ro i8/1C",
        ),
    },
    "mitld_lp.solvers.order_kernels": {
        "renumber_kernel": (
            "i8/1C i8/1C i4/1C i4/1C f8/1C i4/1C",
            "i8/1C i8/1C i8/1C i8/1C f8/1C i4/1C",
        ),
        "value_order_kernel": (
            "i8/1C i4/1C i4/1C f8/1C i4/1C",
            "i8/1C i8/1C i8/1C f8/1C i8/1C",
        ),
    },
    "mitld_lp.solvers.quotient_kernels": {
        "quotient_entries": (
            "i4/1C i4/1C f8/1C i4/1C i4/1C int f8/2C bool f8/1C i4/1C i4/1C f8/2C",
        ),
    },
    "mitld_lp.solvers.topo_kernels": {
        "topo_factor": (
            "i8/1C i8/1C i8/1C i8/1C i8/1C f8/1C i8/1C f8/1C i8/1C f8/1C f8/1C b1/1C",
        ),
        "topo_solve": (
            "i8/1C i8/1C i8/1C i8/1C i8/1C f8/1C i8/1C f8/1C i8/1C f8/1C f8/2C f8/2C f8/2C",
        ),
    },
    "mitld_lp.worlds.prism_kernels": {
        "explore": (
            "i8/1C f8/1C i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C i8/1C "
            "i8/1C i8/1C np.i8 i8/1C i8/1C i8/1C i8/1C np.i8 np.i8 np.i8 i8/1C i4/1C i8/1C i8/1C "
            "i8/1C f8/1C i8/1C i8/1C",
        ),
        "label_flags": (
            "i8/1C f8/1C i8/1C i8/1C np.i8 i8/1C i8/1C i8/1C i8/1C i8/1C",
        ),
        "rehash": (
            "i8/1C np.i8 np.i8 np.i8",
        ),
    },
}
"""Kernel module -> kernel's name -> its signatures, each as :func:`encode` writes it."""


def encode(key: tuple) -> str:
    """A :func:`~mitld_lp.util.kernel_types.type_key` as one short string: an array as
    ``f8/1C`` (dtype, dimensions, layout C / F / A) with ``/ro`` where read-only and
    ``/un`` where unaligned, a NumPy scalar as ``np.i8``, a Python scalar by its type's
    name; the arguments separated by spaces (``""``: none)."""
    words = []
    for part in key:
        if part[0] == "array":
            dtype, ndim, layout, readonly, aligned = part[1:]
            words.append(f"{np.dtype(dtype).str[1:]}/{ndim}{layout}"
                         + ("/ro" if readonly else "") + ("" if aligned else "/un"))
        elif part[0] == "scalar":
            words.append(f"np.{np.dtype(part[1]).str[1:]}")
        else:
            words.append(part[0])
    return " ".join(words)


def decode(text: str) -> tuple:
    """The type key :func:`encode` wrote as ``text``; ValueError naming the word it
    cannot read."""
    key: list[tuple] = []
    for word in text.split():
        if word in ("int", "float", "bool"):
            key.append((word,))
        elif word.startswith("np."):
            key.append(("scalar", np.dtype(word[3:]).str))
        elif "/" in word:
            dtype, shape, *flags = word.split("/")
            if (len(shape) != 2 or not shape[0].isdigit() or shape[1] not in "CFA"
                    or not set(flags) <= {"ro", "un"}):
                raise ValueError(f"not an argument type: {word!r} in {text!r}")
            key.append(("array", np.dtype(dtype).str, int(shape[0]), shape[1],
                        "ro" in flags, "un" not in flags))
        else:
            raise ValueError(f"not an argument type: {word!r} in {text!r}")
    return tuple(key)


def signatures() -> Iterator[tuple[str, str, tuple]]:
    """(module, kernel's name, type key) of every listed signature."""
    for module, kernels in SIGNATURES.items():
        for name, keys in kernels.items():
            for text in keys:
                yield module, name, decode(text)


def compile_all(progress: Callable[[str], None] | None = None) -> tuple[int, int, float]:
    """Compile every listed signature the loader would not link from its cache: (how
    many were compiled, how many listed, CPU seconds).  Nothing where numba is not
    installed ((0, 0, 0.0): the solve then runs its NumPy routes)."""
    from mitld_lp.util.kernel_types import sample_args

    start = time.process_time()
    compiled = listed = 0
    for module, name, key in signatures():
        try:
            kernels = importlib.import_module(module)
        except ImportError:  # numba missing (lazy_numba says so): nothing to compile
            return 0, 0, 0.0
        listed += 1
        if getattr(kernels, name).compile_for(sample_args(key)):
            compiled += 1
            if progress is not None:
                progress(f"{module}.{name}({encode(key)})")
    return compiled, listed, time.process_time() - start


def record(force_gates: bool = False) -> set[tuple[str, str, str]]:
    """From now on in this process, every kernel call's (module, kernel's name, encoded
    type key; ``"?"`` where the loader would not key it) is added to the set returned:
    how :data:`SIGNATURES` is found and checked.  ``force_gates``: every kernel counts
    as cached and its load as paid (:func:`~mitld_lp.util.kernel_loader.cached`,
    :func:`~mitld_lp.util.kernel_loader.compiled_paid`), so that the gates that ask
    take the compiled routes their sizes allow.  A kernel called inside another's call
    (numba disabled: the kernels run as Python) is not recorded: numba compiles it into
    its caller."""
    from mitld_lp.util import kernel_loader
    from mitld_lp.util.kernel_types import type_key

    seen: set[tuple[str, str, str]] = set()
    call = kernel_loader.Kernel.__call__
    depth = [0]  # a kernel's call of a kernel (numba off: Python's) is compiled into it

    def recorded(self: kernel_loader.Kernel, *args: object, **kwargs: object) -> object:
        if not depth[0]:
            key = None if kwargs or not self.cacheable() else type_key(args)
            seen.add((self.__module__, self.__qualname__,
                      "?" if key is None else encode(key)))
        depth[0] += 1
        try:
            return call(self, *args, **kwargs)
        finally:
            depth[0] -= 1

    kernel_loader.Kernel.__call__ = recorded
    if force_gates:
        kernel_loader.cached = lambda *_: True
        kernel_loader.compiled_paid = lambda: True
    return seen

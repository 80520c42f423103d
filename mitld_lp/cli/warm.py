"""The command line's ``warm`` verb: compile, once on a machine, the own PRISM explorer's
kernels (:mod:`mitld_lp.worlds.prism_explore`), which a PRISM or JANI load uses only
where their machine code is cached already; until then Storm's explicit builder builds
every PRISM world (the same tables, slower).  Also the lifted policy's kernel
(:mod:`mitld_lp.solvers.lift_kernels`), which a solve uses only where it is cached
(until then the NumPy search: the same choices), and the blocks' cut
(:mod:`mitld_lp.solvers.block_kernels`), likewise.  Then every other kernel signature a
solve may link (:data:`mitld_lp.util.warm_kernels.SIGNATURES`: the analysis's, the
iteration's, the certificate's, the quotient's, the LP's lift, the step-bounded and the
sensed routes'), which a first solve on a machine compiled otherwise (seconds each)."""

from __future__ import annotations

import argparse
import time

from mitld_lp.cli.kernel import EXIT_OK, say, say_answer

__all__ = ["args_warm", "cmd_warm"]


def args_warm(p: argparse.ArgumentParser) -> None:
    del p  # no arguments: the kernels are the package's own


def cmd_warm(args: argparse.Namespace) -> int:
    """Compile the explorer's kernels if they are not cached; say which it was."""
    from mitld_lp.worlds.prism import stormpy_module
    from mitld_lp.worlds.prism_explore import compile_kernels, kernel_ready

    if not kernel_ready() and not args.quiet:  # half a minute with nothing else said
        say("compiling the own PRISM explorer (about half a minute of CPU, once)")
    start = time.process_time()
    if compile_kernels(stormpy_module()):
        say_answer(f"compiled the own PRISM explorer's kernels in "
                   f"{time.process_time() - start:.1f} s of CPU; PRISM files are now "
                   f"built with them")
    else:
        say_answer("the own PRISM explorer's kernels were compiled already")
    from mitld_lp.solvers.topo_chain import compile_kernels as compile_chain_kernels

    start = time.process_time()
    if compile_chain_kernels():  # the policy jump's chain solve (seconds, once)
        say_answer(f"compiled the policy jump's chain kernels in "
                   f"{time.process_time() - start:.1f} s of CPU")
    _warm_kernel("lift_kernels", "first_staying_kernel", "the lifted policy's kernel")
    _warm_kernel("block_kernels", "split_rows_kernel", "the blocks' cut")
    _warm_solve(args)
    return EXIT_OK


def _warm_solve(args: argparse.Namespace) -> None:
    """Compile (or find cached) every listed signature of the solve's kernels; say how
    many were compiled and the CPU it took."""
    from mitld_lp.util import warm_kernels

    if not args.quiet:
        say("the solve's kernels: compiling those not cached (minutes of CPU, once)")
    compiled, listed, cpu = warm_kernels.compile_all()
    if not listed:
        say_answer("numba is not installed: the solve runs its NumPy routes")
    elif compiled:
        say_answer(f"compiled {compiled} of the solve's {listed} kernel signatures in "
                   f"{cpu:.1f} s of CPU; a first solve now links them from the cache")
    else:
        say_answer(f"the solve's {listed} kernel signatures were compiled already")


def _warm_kernel(name: str, qualname: str, label: str) -> None:
    """Compile (or find cached) the kernel ``qualname`` of the solver's module ``name``
    by its ``warm_up``; nothing where numba is not installed (the solve then takes its
    NumPy route: the same answers)."""
    import importlib

    try:
        module = importlib.import_module(f"mitld_lp.solvers.{name}")
    except ImportError:
        return
    from mitld_lp.util import kernel_loader

    cached = kernel_loader.cached(module.__file__, qualname)
    start = time.process_time()
    module.warm_up()
    if not cached:
        say_answer(f"compiled {label} in {time.process_time() - start:.1f} s of CPU")

"""The command line's ``export`` verb: the occupancy LP (MPS/LP), the product MDP (Storm's
DRN) and, for a law known only within a band, the interval MDP (DRN with intervals).
Wired into :mod:`mitld_lp.cli` (which owns exit codes and error lines)."""

from __future__ import annotations

import argparse
from pathlib import Path

from mitld_lp import files
from mitld_lp.cli import EXIT_OK, UsageError, _args_model, _build, _out, _output_path, _write

__all__ = ["args_export", "cmd_export"]


def args_export(p: argparse.ArgumentParser) -> None:
    _args_model(p)
    p.add_argument("--lp", metavar="FILE",
                   help="the occupancy LP, whose optimum is the value, as .mps or .lp")
    p.add_argument("--drn", metavar="FILE", help="the product MDP in Storm's DRN format")
    p.add_argument("--upper", action="store_true",
                   help="count the truncation sink as winning (the upper model)")
    p.add_argument("--force", action="store_true", help="overwrite existing files")


def cmd_export(args: argparse.Namespace) -> int:
    """Write the LP (through HiGHS) and/or the MDP (DRN) for external tools."""
    from mitld_lp.solvers.export import DRN_SUFFIXES, LP_SUFFIXES, write_drn, write_lp

    if args.lp is None and args.drn is None:
        raise UsageError("export: nothing to do; give --lp FILE and/or --drn FILE")
    lp = None if args.lp is None else _output_path(args.lp, args.force, "--lp", LP_SUFFIXES)
    drn = None if args.drn is None else _output_path(args.drn, args.force, "--drn",
                                                     DRN_SUFFIXES)
    files.distinct_outputs((what, p) for what, p in (("--lp", lp), ("--drn", drn)) if p)
    from mitld_lp.acceptance import acceptance

    if _robust_export(args, lp, drn):
        return EXIT_OK
    built = _build(args)[1]
    mdp = built.mdp
    goal = acceptance(mdp, built.dta).goal  # a safety task: its accepting end components
    target = goal | mdp.truncated if args.upper else goal
    if lp:
        _write(lp, lambda p: write_lp(mdp, target, p, overwrite=True))
        _out(f"wrote {lp}")
    if drn:
        _write(drn, lambda p: write_drn(mdp, target, p, overwrite=True))
        _out(f"wrote {drn}")
    return EXIT_OK


def _robust_export(args: argparse.Namespace, lp: Path | None, drn: Path | None) -> bool:
    """A model with a law known only within a band: its interval MDP as DRN (the robust
    optimum is a max-min, no one LP: --lp is refused).  False for any other model."""
    from mitld_lp.model import load_model
    from mitld_lp.robust_synthesis import interval_model, is_robust
    from mitld_lp.solvers.robust_export import write_interval_drn

    model = load_model(args.model, max_states=args.max_world_states,
                       max_memory=args.max_memory)
    if not is_robust(model.distributions):
        return False
    if lp:
        raise UsageError("export --lp: a law known only within a band has a robust optimum "
                         "(a max-min), which is no single LP; export --drn writes the "
                         "interval MDP")
    imdp = interval_model(model, epsilon=args.epsilon,
                          clock_reduction=not args.no_clock_reduction,
                          max_states=args.max_states, max_memory=args.max_memory,
                          max_automaton_states=args.max_automaton_states)
    target = imdp.target | imdp.truncated if args.upper else imdp.target
    assert drn is not None  # export checked that one of the two is given
    _write(drn, lambda p: write_interval_drn(imdp, target, p, overwrite=True))
    _out(f"wrote {drn} (interval MDP)")
    return True

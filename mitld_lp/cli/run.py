"""The command line's ``run`` verb: a saved controller answering observations, one JSON
line in, one JSON line out.  The command is :func:`mitld_lp.runtime.main` (NumPy alone),
which the console script reaches before it imports this package
(:func:`mitld_lp.startup.command`); this module registers the verb in
:data:`mitld_lp.cli._VERBS` (its help, and the path through the whole command line when
``--time-limit`` is given) and runs the same :func:`mitld_lp.runtime.run_file`."""

from __future__ import annotations

import argparse

__all__ = ["args_run", "cmd_run"]


def args_run(p: argparse.ArgumentParser) -> None:
    p.add_argument("controller", metavar="CONTROLLER",
                   help="a controller file saved by Controller.save / solve --controller")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of a randomised controller's generator (default 0)")


def cmd_run(args: argparse.Namespace) -> int:
    """Answer each line of stdin, ``{"state": ..., "events": [...]}``, with a line
    ``{"action": ..., "status": ...}`` on stdout (``{"error": ...}`` for a bad line,
    and the loop goes on).  Exit 0; 2 when the file is not a controller or some line
    was bad (the count is said on stderr)."""
    from mitld_lp.runtime import run_file

    return run_file(args.controller, seed=args.seed)

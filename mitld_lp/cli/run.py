"""The command line's ``run`` verb: a saved controller answering observations, one JSON
line in, one JSON line out (:func:`mitld_lp.runtime.serve`), for any robot stack to
drive.  It imports :mod:`mitld_lp.runtime` only (NumPy; no solver, parser or world).
Registered in :data:`mitld_lp.cli._VERBS`; it imports nothing of the command line
(no import circle), so it says its own one error line."""

from __future__ import annotations

import argparse
import sys

__all__ = ["args_run", "cmd_run"]

EXIT_OK, EXIT_USAGE = 0, 2


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
    from mitld_lp.runtime import ControllerFileError, load

    if args.seed < 0:
        return _error(f"--seed: must be >= 0, got {args.seed}")
    try:
        controller = load(args.controller, seed=args.seed)
    except ControllerFileError as err:
        return _error(str(err))
    bad = controller_loop(controller)
    if bad:
        return _error(f"run: {bad} observation line{'s' if bad > 1 else ''} could not be "
                      "answered (each got an error line)")
    return EXIT_OK


def controller_loop(controller: object) -> int:
    from mitld_lp.runtime import RuntimeController, serve

    assert isinstance(controller, RuntimeController)
    return serve(controller, sys.stdin, sys.stdout)


def _error(message: str) -> int:
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in message)
    print(f"mitld-lp: error: {text}", file=sys.stderr, flush=True)
    return EXIT_USAGE

"""The command line's ``export`` verb: the occupancy LP (MPS/LP), the product MDP (Storm's
DRN) and, for a law known only within a band, the interval MDP (DRN with intervals);
and, from a synthesis, its controller (``--controller``), the controlled chain
(``--chain``, :mod:`mitld_lp.running.chain`) and the decision tree (``--tree``,
:mod:`mitld_lp.running.tree`).  Wired into :mod:`mitld_lp.cli` (which owns exit codes and error
lines)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mitld_lp.cli.kernel import (
    EXIT_OK,
    EXIT_UNCERTIFIED,
    UsageError,
    add_model_argument,
    args_json,
    build_for,
    json_text,
    output_path,
    read_model,
    say_answer,
    time_left,
    write_file,
)
from mitld_lp.files import write as files

__all__ = ["args_export", "cmd_export"]


def args_export(p: argparse.ArgumentParser) -> None:
    add_model_argument(p)
    p.add_argument("--lp", metavar="FILE",
                   help="the occupancy LP, whose optimum is the value, as .mps or .lp")
    p.add_argument("--drn", metavar="FILE", help="the product MDP in Storm's DRN format")
    p.add_argument("--controller", metavar="FILE",
                   help="the synthesised controller (.npz), for Controller.load and mitld-lp run")
    p.add_argument("--chain", metavar="FILE", help="the Markov chain of the world under the "
                   "controller (Storm's DRN; P=? [F \"accept\"] is the value)")
    p.add_argument("--tree", metavar="FILE", help="the controller as an exact decision tree: "
                   ".json, .dot or .py")
    p.add_argument("--same-actions", action="store_true", help="the tree picks the "
                   "controller's own action everywhere (else any action keeping its value)")
    p.add_argument("--upper", action="store_true",
                   help="count the truncation sink as winning (the upper model)")
    p.add_argument("--force", action="store_true", help="overwrite existing files")
    args_json(p)


def cmd_export(args: argparse.Namespace) -> int:
    """Write the LP (through HiGHS) and/or the MDP (DRN) for external tools; with
    ``--json`` one object: the files written, and the synthesis's status for the
    controller's exports."""
    said: dict[str, Any] = {"files": {}}
    code = _export(args, said)
    if args.json:
        say_answer(json_text(said))
    return code


def _wrote(args: argparse.Namespace, said: dict[str, Any], key: str, path: Path, line: str,
           **more: Any) -> None:
    """A file written: its line, or (``--json``) its entry under ``files`` and ``more``."""
    said["files"][key] = str(path)
    said.update(more)
    if not args.json:
        say_answer(line)


def _export(args: argparse.Namespace, said: dict[str, Any]) -> int:
    from mitld_lp.running.tree import TREE_SUFFIXES
    from mitld_lp.solvers.export import DRN_SUFFIXES, LP_SUFFIXES, write_drn, write_lp

    wanted = (args.lp, args.drn, args.controller, args.chain, args.tree)
    if all(w is None for w in wanted):
        raise UsageError("export: nothing to do; give --lp, --drn, --controller, --chain "
                         "or --tree FILE")
    lp = None if args.lp is None else output_path(args.lp, args.force, "--lp", LP_SUFFIXES)
    drn = None if args.drn is None else output_path(args.drn, args.force, "--drn",
                                                    DRN_SUFFIXES)
    controller = None if args.controller is None else output_path(
        args.controller, args.force, "--controller", (".npz",))
    chain = None if args.chain is None else output_path(args.chain, args.force, "--chain",
                                                        (".drn",))
    tree = None if args.tree is None else output_path(args.tree, args.force, "--tree",
                                                      TREE_SUFFIXES)
    files.distinct_outputs((what, p) for what, p in (
        ("--lp", lp), ("--drn", drn), ("--controller", controller), ("--chain", chain),
        ("--tree", tree)) if p)
    if args.same_actions and tree is None:
        raise UsageError("export --same-actions: a choice for --tree; give --tree FILE")
    code = EXIT_OK
    if controller or chain or tree:
        code = _controller_exports(args, said, controller, chain, tree)
    if lp is None and drn is None:
        return code
    from mitld_lp.routes.acceptance import acceptance

    if _robust_export(args, said, lp, drn):
        return code
    posed, built = build_for(args, "export")
    if posed.minimise:
        raise UsageError("export: the model's objective is min; the LP and the DRN's "
                         "target are written for a maximum (not exported, to keep the "
                         "files' optimum the task's)")
    mdp = built.mdp
    goal = acceptance(mdp, built.dta).goal  # a safety task: its accepting end components
    target = goal | mdp.truncated if args.upper else goal
    if lp:
        write_file(lp, lambda p: write_lp(mdp, target, p, overwrite=True))
        _wrote(args, said, "lp", lp, f"wrote {lp}")
    if drn:
        world = _world_valuation(posed.model.game)
        write_file(drn, lambda p: write_drn(mdp, target, p, overwrite=True, world=world))
        _wrote(args, said, "drn", drn, f"wrote {drn}")
    return code


def _world_valuation(game: Any) -> Callable[[object], str] | None:
    """How the DRN names a world state: a PRISM world's by its variables (``x=2 &
    open=true``, as Storm's own exporter names PRISM states); any other world's as
    ``game=...`` (None: the default)."""
    from mitld_lp.worlds.names import state_values, valuation_text, world_variables

    names = world_variables(game)
    if names is None:
        return None
    return lambda g: valuation_text(names, state_values(game, g))  # type: ignore[arg-type]


def _controller_exports(args: argparse.Namespace, said: dict[str, Any],
                        controller: Path | None, chain: Path | None,
                        tree: Path | None) -> int:
    """Synthesise (the model's own problem: constraints give a randomised controller)
    and write its controller, chain and tree; exit 3 when the answer is not certified
    (the files are written all the same, and say what they are)."""
    from mitld_lp.files import drn
    from mitld_lp.running.band_chain import band_chain_drn, band_chain_of, band_claim, is_band
    from mitld_lp.running.band_mixture_chain import (
        is_band_mixture,
        mixture_chain_drn,
        mixture_claim,
    )
    from mitld_lp.running.chain import chain_drn, chain_of
    from mitld_lp.running.optimistic_chain import (
        is_optimistic,
        optimistic_chain_of,
        optimistic_claim,
    )
    from mitld_lp.running.tree import tree_of
    from mitld_lp.synthesis import synthesize

    if args.upper:
        raise UsageError("export --upper: the upper model has no controller of its own; "
                         "--controller, --chain and --tree export the synthesised one")
    model = read_model(args)
    r = synthesize(model, epsilon=args.epsilon, clock_reduction=not args.no_clock_reduction,
                   max_states=args.max_states, max_memory=args.max_memory,
                   max_automaton_states=args.max_automaton_states,
                   time_limit=time_left(args), bands=args.bands)
    if r.controller is None:
        raise UsageError(f"export: no controller to write: the synthesis is {r.status}")
    said.update(status=str(r.status), certified=r.certified, lower=r.lower, upper=r.upper)
    if controller:
        from mitld_lp.problem import Settings

        budget = Settings(max_states=args.max_states).resolved(model.budgets).max_states
        write_file(controller, lambda p: r.controller.save(p, overwrite=True,
                                                       max_states=budget))
        _wrote(args, said, "controller", controller, f"wrote {controller}")
    from mitld_lp.running.sensed_band_chain import (
        is_sensed_band,
        sensed_band_claim,
        sensed_band_drn,
    )
    from mitld_lp.running.sensed_optimistic_chain import is_sensed_optimistic

    if chain and (is_optimistic(r) or is_sensed_optimistic(r)):  # the best law: a plain
        # chain at nature's chosen law (with sensors, over the truth and the memory)
        plain = chain_drn(optimistic_chain_of(r) if is_optimistic(r) else chain_of(r))
        write_file(chain, lambda p: drn.write(plain, p, overwrite=True))
        accept, said_chain = optimistic_claim(r)
        _wrote(args, said, "chain", chain, f"wrote {chain} ({said_chain})", chain_accept=accept)
    elif chain and is_sensed_band(r):  # sensors and a band: an interval chain too
        band = sensed_band_drn(r)  # its rewards too (constraints, then)
        write_file(chain, lambda p: drn.write(band, p, overwrite=True))
        accept, said_chain = sensed_band_claim(r)
        _wrote(args, said, "chain", chain, f"wrote {chain} ({said_chain})", chain_accept=accept)
    elif chain and is_band(r):  # the interval chain, for Storm's robust check
        band = band_chain_drn(band_chain_of(r))
        write_file(chain, lambda p: drn.write(band, p, overwrite=True))
        accept, said_chain = band_claim(r)
        _wrote(args, said, "chain", chain, f"wrote {chain} ({said_chain})", chain_accept=accept)
    elif chain and is_band_mixture(r):  # randomised, with a band: nature's corners
        mixed = mixture_chain_drn(r)
        write_file(chain, lambda p: drn.write(mixed, p, overwrite=True))
        accept, said_chain = mixture_claim(r)
        _wrote(args, said, "chain", chain, f"wrote {chain} ({said_chain})", chain_accept=accept)
    elif chain:
        model = chain_drn(chain_of(r))
        write_file(chain, lambda p: drn.write(model, p, overwrite=True))
        # the chain's probability is the controller's exact value: inside the bracket of
        # the automaton it was solved on, at its near end within the precision
        if r.complemented:  # the complement's automaton: "accept" marks failing runs
            accept = r.complement[0] if r.complement is not None else 1.0 - r.upper
            said_chain = (f"P=? [F \"accept\"] >= the complement's lower = {accept!r}: for a "
                          "minimised task \"accept\" marks the runs that fail it")
        elif r.objective == "min":  # the controller's guarantee counts truncation in
            accept = r.upper
            said_chain = (f"P=? [F (\"accept\" | \"truncated\")] <= upper = {accept!r}: for "
                          "a minimised task the runs past a truncation point count as the "
                          "task's")
        else:
            accept = r.lower
            said_chain = f"P=? [F \"accept\"] >= lower = {accept!r}"
            said_chain += _sensed_claims(r)
        _wrote(args, said, "chain", chain, f"wrote {chain} ({said_chain})", chain_accept=accept)
    if tree:
        from mitld_lp.running.tree import write_tree

        t = tree_of(r, same_actions=args.same_actions)
        write_file(tree, lambda p: write_tree(r, p, tree=t, overwrite=True))
        rows = len(r.policy_table())
        _wrote(args, said, "tree", tree, f"wrote {tree} ({t.size} nodes over {t.samples} "
               f"reachable states; policy table: {rows} rows)", tree_nodes=t.size,
               tree_states=t.samples)
    if not r.certified:
        if not args.json:
            say_answer(f"not certified: {r.status}")
        return EXIT_UNCERTIFIED
    return EXIT_OK


def _sensed_claims(r: Any) -> str:
    """What the chain of a sensed answer with constraints or ``then`` claims beside the
    task (:mod:`mitld_lp.running.sensed_joint`'s labels and reward): each ``P(...)``
    constraint's probability, each ``E(steps)`` or ``E(cost)`` bound and the ``then``
    value (rewards ``steps`` and ``cost``); empty for any other answer."""
    from mitld_lp.running.sensed_chain import is_sensed

    if not (is_sensed(r) and getattr(r.part, "randomised", False)):
        return ""
    out = []
    for i, v in enumerate(r.constraints, start=1):
        c = v.constraint
        if c.kind == "prob":
            out.append(f"P=? [F \"c{i}\"] {c.sense} {v.certified!r} ({c})")
        else:
            out.append(f"R{{\"{c.kind}\"}}=? [F \"done\"] <= {v.certified!r} ({c})")
    if r.then is not None and r.secondary is not None:
        kind = r.then.removeprefix("min-")
        out.append(f"R{{\"{kind}\"}}=? [F \"done\"] ~= {r.secondary!r} (then {r.then}, "
                   "the LP's value)")
    return "".join("; " + x for x in out)


def _robust_export(args: argparse.Namespace, said: dict[str, Any], lp: Path | None,
                   drn: Path | None) -> bool:
    """A model with a law known only within a band: its interval MDP as DRN (the robust
    optimum is a max-min, no one LP: --lp is refused).  False for any other model."""
    from mitld_lp.cli.kernel import posed_model
    from mitld_lp.routes.robust import interval_export, is_robust
    from mitld_lp.solvers.robust_export import write_interval_drn

    model = read_model(args)
    if not is_robust(model.distributions):
        return False
    posed = posed_model(args, model, "export")
    if posed.minimise:
        raise UsageError("export: the model's objective is min; not exported (the "
                         "interval MDP would be the complement's)")
    if lp:
        raise UsageError("export --lp: a law known only within a band has a robust optimum "
                         "(a max-min), which is no single LP; export --drn writes the "
                         "interval MDP")
    s = posed.settings
    assert s.max_states is not None and s.max_automaton_states is not None  # resolved
    imdp, target = interval_export(  # a safety part: the states where it is kept robustly
        model, upper=args.upper, epsilon=s.epsilon, clock_reduction=s.clock_reduction,
        max_states=s.max_states, max_memory=s.max_memory,
        max_automaton_states=s.max_automaton_states)
    assert drn is not None  # export checked that one of the two is given
    write_file(drn, lambda p: write_interval_drn(imdp, target, p, overwrite=True))
    _wrote(args, said, "drn", drn, f"wrote {drn} (interval MDP)", interval_mdp=True)
    return True

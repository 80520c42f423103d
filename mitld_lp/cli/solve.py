"""The command line's ``info`` (the product's sizes) and ``solve`` (the certified answer)
verbs; a batch of model files goes to :mod:`mitld_lp.cli.runs`, a constrained problem's
printing to :mod:`mitld_lp.cli.constrained`."""

from __future__ import annotations

import argparse
from typing import Any

from mitld_lp import defaults
from mitld_lp.cli import constrained, door
from mitld_lp.cli.arguments import solver_name
from mitld_lp.cli.kernel import (
    EXIT_OK,
    EXIT_UNCERTIFIED,
    UsageError,
    add_model_argument,
    args_json,
    build_for,
    is_pattern,
    json_text,
    output_path,
    print_head,
    prob_text,
    read_model,
    say_answer,
    solve_settings,
    write_file,
)
from mitld_lp.files import write as files
from mitld_lp.report import bracket_text

__all__ = ["args_info", "cmd_info", "args_solve", "cmd_solve"]


def args_info(p: argparse.ArgumentParser) -> None:
    add_model_argument(p)
    args_json(p)


def cmd_info(args: argparse.Namespace) -> int:
    """The product's sizes, truncation points and the epsilon achieved."""
    from mitld_lp.product import component_counts

    posed, built = build_for(args, "info")
    model = posed.model
    sta, mdp = built.sta, built.mdp
    out: dict[str, Any] = {
        "model": model.name,
        "spec": str(model.spec),
        "objective": posed.problem.objective,
        "dta_states": sta.dta.n_states,
        **component_counts(mdp),
        "truncation_points": sta.truncation_points,
        "epsilon": model.epsilon if posed.settings.epsilon is None else posed.settings.epsilon,
        "epsilon_achieved": sta.epsilon_achieved,
    }
    if args.json:
        say_answer(json_text(out))
    else:
        width = max(map(len, out))
        for k, v in out.items():
            say_answer(f"{k + ':':<{width + 1}} {v}")
    return EXIT_OK


def args_solve(p: argparse.ArgumentParser) -> None:
    add_model_argument(p, many=True)
    p.add_argument("--method", choices=defaults.METHODS, default="lp")
    p.add_argument("--solver", type=solver_name, default=defaults.SOLVER,
                   help="an LP solver cvxpy has installed, any case (CLARABEL, HIGHS, ...)")
    p.add_argument("--backend", choices=defaults.BACKENDS, default="auto",
                   help="direct: Clarabel on the sparse matrices; cvxpy: through cvxpy "
                        "(any solver); auto (default): direct for Clarabel, else cvxpy")
    p.add_argument("--no-decompose", action="store_true",
                   help="solve one monolithic LP instead of one LP per strongly connected "
                        "block in topological order")
    p.add_argument("--exact", action="store_true",
                   help="also the exact optimum as a fraction, in rational arithmetic on the "
                        "model as written (models of modest size; grid and PRISM worlds; "
                        "geometric, pmf and uniform laws)")
    args_json(p)
    p.add_argument("--policy", metavar="FILE",
                   help="write the policy table (.csv or .json): one row per state")
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    constrained.args_constraints(p)
    door.args_door(p)


def cmd_solve(args: argparse.Namespace) -> int:
    """Synthesise the policy: the certified bracket, the value, the sizes."""
    from mitld_lp.synthesis import pose, solve

    if args.backend == "direct" and args.solver != "CLARABEL":
        raise UsageError(f"--backend direct runs only Clarabel, not {args.solver}; "
                         "use --backend cvxpy (or auto) for other solvers")
    world = door.check_args(args)  # a PRISM file with --prop or --spec
    if not world and (len(args.model) > 1 or is_pattern(args.model[0])):
        from mitld_lp.cli import runs  # a batch's verb (0.007 s of CPU a single model skips)

        return runs.solve_batch(args)
    args.model = args.model[0]
    policy_file = None if args.policy is None else output_path(
        args.policy, args.force, "--policy", files.POLICY_SUFFIXES)
    if world and args.spec is None:  # --prop, or a JANI file's own properties
        return door.solve_properties(args, policy_file)
    if args.objective in ("min-steps", "min-cost"):  # the expected steps (cost)
        from mitld_lp.cli.steps import solve_steps  # its solver loads only when asked

        return solve_steps(args, world, policy_file)
    model = door.world_model(args) if world else read_model(args)
    posed = pose(model, args.constraint, then=args.then,
                 settings=solve_settings(args), objective=args.objective)
    if posed.route.takes_constraints:
        return constrained.solve(args, posed, policy_file)
    r = solve(posed)
    summary = r.summary()
    if policy_file:
        write_file(policy_file, lambda p: files.write_policy(r, p, overwrite=True))
        summary["policy_file"] = str(policy_file)
    if args.json:
        say_answer(json_text(summary))
    else:
        print_head(model, r.objective)
        if summary["robust"]:
            said = ("worst case over the bands " if summary["bands_reading"] == "worst"
                    else "best case over the bands (Pmaxmax) ")
            say_answer("robust:       " + said + ", ".join(
                f"{e} ~ {law} (hazard at step 1 in [{prob_text(h[0])}, {prob_text(h[1])}])"
                for (e, law), h in zip(summary["bands"].items(),
                                       summary["first_step_hazards"].values(), strict=True)))
        if r.sensors:
            say_answer("sensed:       the policy acts on what the robot observes; " + ", ".join(
                f"{e} reported w.p. {sensor.detect:g} per step"
                + (f" from {sensor.delay} steps after it" if sensor.delay else "")
                + (f", falsely w.p. {sensor.false_alarm:g} before" if sensor.false_alarm
                   else "")
                for e, sensor in sorted(r.sensors.items())))
        say_answer(f"optimum in:   {bracket_text(r.lower, r.upper)}"
              f"  (epsilon achieved {r.sta.epsilon_achieved:.3g})")
        if r.complement is not None:
            say_answer(f"complement:   1 - optimum in {bracket_text(*r.complement)}")
        width = r.width
        if width.get("truncation"):
            say_answer(f"width:        {width['total']:.3g} = truncation {width['truncation']:.3g}"
                       f" (at most epsilon achieved) + solver {width['solver']:.3g}")
        if r.exact is not None:
            say_answer(exact_line(r.exact))
        # a minimum read back from its complement: the complement's estimate, whose
        # digits 1 - it would round away
        shown = (f"1 - {prob_text(r.lower_model.value)}" if r.complemented and
                 r.lower_model is not None else prob_text(r.value))
        say_answer(f"value:        {shown}  ({r.method}, status {r.status.value})")
        say_answer("certified:    " + ("yes" if r.certified else "NO"))
        if summary["bands_reading"] == "best":
            say_answer("note:         the controller reaches this only when the events "
                       "follow the law of the bands that helps it; it guarantees nothing "
                       "under a law nature chooses (--bands worst gives the guarantee)")
        for c in r.failed_checks:
            say_answer(f"  failed: {c.name}: {c.detail}")
        say_answer(f"sizes:        {r.dta.n_states} automaton states, {r.mdp.n_states} states,"
                   f" {r.mdp.n_choices} choices, {r.mdp.n_transitions} transitions")
        if r.sta.truncation_points:
            say_answer(f"truncation:   {r.sta.truncation_points}")
        say_answer("seconds:      " + ", ".join(f"{k} {v:.3f}" for k, v in r.timings.items()))
        if policy_file:
            say_answer(f"policy:       {policy_file}")
    return EXIT_OK if r.certified else EXIT_UNCERTIFIED


def exact_line(exact: Any) -> str:
    """The exact optimum: the fraction, and a float to read it by; with a truncation,
    both models' fractions."""
    if exact.value is not None:
        return f"exact:        {exact.value}  (~ {float(exact.value)!r})"
    return (f"exact:        in [{exact.lower}, {exact.upper}]  (~ [{float(exact.lower)!r}, "
            f"{float(exact.upper)!r}]: the optima of the two truncation models; the "
            "truncation leaves no one value)")

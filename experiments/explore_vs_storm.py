"""The own PRISM explorer (:mod:`mitld_lp.worlds.prism_explore`) against Storm's build on
QVBS's PRISM MDPs: the same model up to state numbering, and the CPU seconds of each.

For every PRISM instance of ``--qvbs``'s ``mdp`` folder with at most ``--max-states``
states by QVBS's count (``--quick``: 20,000), the program with the instance's constants
is built by Storm (``stormpy.build_model`` with every label and the state valuations)
and by the own explorer; the two are the same when they have the same numbers of states,
choices and transitions, the same initial state, and the states matched by their
valuations have the same multiset of choices (each a sorted tuple of (successor's
valuation, probability), floats compared exactly) and the same labels.  Printed per
instance: supported or the reason, states, transitions, Storm's build CPU s, ours (the
compile and the exploration; the kernel already compiled), ratio, equal or not, and
whether the numbering is Storm's own (the same state at the same index).

    python experiments/explore_vs_storm.py --qvbs /work/shared/qvbs [--quick] \\
        [--only csma consensus] [--max-states 1000000]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def storm_model(stormpy, program, checks: bool = True):
    """Storm's build with every label and the valuations; with its exploration checks,
    else (a sum within PRISM's tolerance only, as the load does) without them."""
    options = stormpy.BuilderOptions()
    options.set_build_all_labels()
    options.set_build_state_valuations()
    options.set_exploration_checks(checks)
    try:
        return stormpy.build_model[float](program, options=options)
    except RuntimeError as exc:
        if not checks or "sum to" not in str(exc):
            raise
    return storm_model(stormpy, program, checks=False)


def storm_arrays(model):
    """(values n x k by name order, choices, branches, targets, probs, labels, init)."""
    from mitld_lp.worlds.prism_tables import read_export, valuations_of

    (choices, branches, targets, probs), packed = read_export(model, "storm")
    names, states = valuations_of(model, packed=packed)
    labels = {lab: np.isin(np.arange(model.nr_states),
                           np.fromiter(model.labeling.get_states(lab), dtype=np.int64))
              for lab in model.labeling.get_labels()}
    return names, np.asarray(states.values, dtype=np.int64), choices, branches, targets, \
        probs, labels, list(model.initial_states)


def signature(names, values, choices, branches, targets, probs, order):
    """Per state (keyed by its valuation in ``order``): the sorted multiset of choices."""
    idx = [names.index(x) for x in order]
    keys = [tuple(r) for r in values[:, idx].tolist()]
    out = {}
    for s in range(len(keys)):
        rows = []
        for c in range(choices[s], choices[s + 1]):
            lo, hi = branches[c], branches[c + 1]
            pairs = zip(targets[lo:hi].tolist(), probs[lo:hi].tolist(), strict=True)
            rows.append(tuple(sorted((keys[t], float(p)) for t, p in pairs)))
        out[keys[s]] = tuple(sorted(rows))
    return out, keys


def compare(stormpy, program) -> dict:
    from mitld_lp.worlds import prism_explore
    from mitld_lp.worlds.prism_compile import Unsupported, compile_program

    row: dict = {}
    t0 = time.process_time()
    model = storm_model(stormpy, program)
    row["storm_cpu"] = time.process_time() - t0
    row["states"], row["transitions"] = model.nr_states, model.nr_transitions
    t0 = time.process_time()
    try:
        compiled = compile_program(program)
    except Unsupported as exc:
        row["supported"] = f"fallback: {exc}"
        return row
    built = prism_explore.explore_program(compiled, 1 << 40)
    row["own_cpu"] = time.process_time() - t0
    if isinstance(built, str):
        row["supported"] = f"fallback: {built}"
        return row
    row["supported"] = "yes"
    row["ratio"] = row["own_cpu"] / max(row["storm_cpu"], 1e-9)
    names, values, choices, branches, targets, probs, labels, init = storm_arrays(model)
    order = sorted(names)
    if sorted(compiled.names) != order:
        row["equal"] = f"variables differ: {compiled.names} vs {names}"
        return row
    n, m, b = len(built.choices) - 1, len(built.branches) - 1, len(built.targets)
    counts = (n, m, b) == (model.nr_states, model.nr_choices, model.nr_transitions)
    mine, my_keys = signature(compiled.names, built.values, built.choices, built.branches,
                              built.targets, built.probabilities, order)
    theirs, their_keys = signature(names, values, choices, branches, targets, probs, order)
    same = counts and mine == theirs
    ours_l = prism_explore.label_values(built, compiled.label_expr)
    at = {k: i for i, k in enumerate(my_keys)}
    perm = np.array([at.get(k, -1) for k in their_keys])
    same_labels = bool((perm >= 0).all())
    for k, lab in enumerate(compiled.labels):
        same_labels &= bool((ours_l[perm, k] == labels[lab]).all())
    dead = np.zeros(n, dtype=bool)
    loops = np.flatnonzero(built.origin == -1)
    dead[np.searchsorted(built.choices, loops, side="right") - 1] = True
    same_labels &= bool((dead[perm] == labels.get("deadlock", np.zeros(n, bool))).all())
    same_init = [their_keys[i] for i in init] == [my_keys[0]]
    row["equal"] = bool(same and same_labels and same_init)
    row["storm_numbering"] = bool(counts and my_keys == their_keys)
    if not row["equal"]:
        row["why"] = (f"counts {counts} choices {mine == theirs} labels {same_labels} "
                      f"init {same_init}")
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--qvbs", type=Path, required=True)
    ap.add_argument("--max-states", type=int, default=1_000_000)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", nargs="*", default=None, help="families")
    ap.add_argument("--out", type=Path, default=None, help="a JSON file of the rows")
    args = ap.parse_args(argv)
    if args.out is not None and args.out.exists():  # never over a file already there
        ap.error(f"--out {args.out}: the file exists; give a new name")
    import qvbs
    import stormpy

    cap = 20_000 if args.quick else args.max_states
    instances, _ = qvbs.find_instances(args.qvbs, cap)
    seen, rows = set(), []
    for inst in instances:
        key = (str(inst.prism), tuple(sorted(inst.constants.items())))
        if key in seen or (args.only and inst.family not in args.only):
            continue
        seen.add(key)
        program = stormpy.parse_prism_program(str(inst.prism))
        undefined = {c.name for c in program.constants if not c.defined}
        given = {k: v for k, v in inst.constants.items() if k in undefined}
        try:
            if given:
                program, _ = stormpy.instantiate_constants(program, given)
            program = program.substitute_constants()
            row = compare(stormpy, program)
        except Exception as exc:  # noqa: BLE001 - reported per instance
            row = {"supported": f"error: {type(exc).__name__}: {str(exc)[:120]}"}
        row["instance"] = f"{inst.prism.name} {given}"
        rows.append(row)
        print(json.dumps(row), flush=True)
    if args.out:
        args.out.write_text(json.dumps(rows, indent=1))
    bad = [r for r in rows if r.get("equal") is False]
    print(f"{len(rows)} instances, {sum(r.get('equal') is True for r in rows)} equal, "
          f"{len(bad)} different", flush=True)
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Benchmark: formula-to-DTA translation time and automaton size.

Families (each row: parameters, states, milliseconds):

* the paper's formula (target: < 50 ms);
* ``nested-F``: ``F[0,w](p1 & F[0,w](p2 & ... F[0,w] pd))``: every pending obligation of
  every level must be remembered, so the minimal automaton has on the order of
  ``w^d`` states -- an inherent blow-up of explicit automata, not of the translation;
* ``nested-G/F``: ``G[0,w](q1 -> F[0,w](q2 & G[0,w](q3 -> ...)))``, alternating;
* ``nested-X``: ``F[0,w] X F[0,w] X ... p`` (d bounded operators, collapses to one window);
* ``deadlines``: ``F[0,10] p1 & ... & F[0,10] pk`` for k = 2..8 (states: 2^k * 11 + 1);
* ``chain``: ``F[0,k] p`` for k up to 10,000 (k + 3 states).  Minimisation by rounds of
  signature refinement over every state needs k rounds here (quadratic: 2.4 s at
  k = 1,000, 10 s at 2,000, > 120 s at 10,000); recomputing only the states whose
  successors moved takes 0.07 s, 0.4 s at 10,000.  The last line prints the time per
  state relative to the smallest k, which stays near 1 when the cost is linear;
* ``events``: ``D[geometric(0.5)] e_i & F(e_i & F[0,3] A)`` for i < n with a budget of
  1,000 states: the first state alone has 2^n successors, so the budget must stop the
  work while that diagram is combined (3.6 s at n = 12 before, when it was checked only
  once a state was numbered; ~0.1 s now).

Run: ``python experiments/bench_dta.py [--budget SECONDS]``.  Rows whose automaton
would exceed ``--max-states`` are reported as such.
"""

from __future__ import annotations

import argparse
import time

from mitld_lp.automata.translate import TranslationError, to_dta
from mitld_lp.logic.parser import parse
from mitld_lp.logic.syntax import Formula, Prop, always, conj, disj, eventually, neg, nxt

PAPER = "(D[mu1] b1 & F(b1 & F[0,3] A)) | (D[mu2] b2 & F(b2 & F[0,3] B))"


def nested_f(d: int, w: int) -> Formula:
    f: Formula = Prop(f"p{d}")
    for i in reversed(range(1, d)):
        f = eventually(conj(Prop(f"p{i}"), f), (0, w))
    return eventually(f, (0, w))


def nested_gf(d: int, w: int) -> Formula:
    f: Formula = Prop(f"q{d}")
    for i in reversed(range(1, d + 1)):
        if i % 2:
            f = always(disj(neg(Prop(f"q{i}")), f), (0, w))
        else:
            f = eventually(conj(Prop(f"q{i}"), f), (0, w))
    return f


def nested_x(d: int, w: int) -> Formula:
    f: Formula = Prop("p")
    for _ in range(d):
        f = eventually(nxt(f), (0, w))
    return f


def deadlines(k: int, w: int = 10) -> Formula:
    return conj(*(eventually(Prop(f"p{i}"), (0, w)) for i in range(1, k + 1)))


def measure(f: Formula, max_states: int) -> tuple[str, float]:
    t = time.perf_counter()
    try:
        n = str(to_dta(f, max_states=max_states).n_states)
    except TranslationError:
        n = f"> {max_states}"
    return n, (time.perf_counter() - t) * 1e3


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-states", type=int, default=20_000)
    ap.add_argument("--quick", action="store_true", help="small sizes only (for tests)")
    args = ap.parse_args(argv)
    widths = (5, 10) if args.quick else (5, 10, 15, 20)
    depths = (1, 2) if args.quick else (1, 2, 3, 4, 6)

    rows: list[tuple[str, str, str, float]] = []
    paper = parse(PAPER)
    to_dta(paper)  # warm the imports (the parser, numpy); each call builds its own memo
    n, ms = measure(paper, args.max_states)
    rows.append(("paper formula", "-", n, ms))
    for name, family in (("nested-F", nested_f), ("nested-G/F", nested_gf),
                         ("nested-X", nested_x)):
        for d in depths:
            for w in widths:
                if name == "nested-F" and w ** d > 50 * args.max_states:
                    rows.append((name, f"d={d} w={w}", f"~{w}^{d} (skipped)", float("nan")))
                    continue
                n, ms = measure(family(d, w), args.max_states)
                rows.append((name, f"d={d} w={w}", n, ms))
    for k in range(2, 5 if args.quick else 9):
        n, ms = measure(deadlines(k), args.max_states)
        rows.append(("deadlines", f"k={k}", n, ms))

    chain = (300, 1000, 3000) if args.quick else (1000, 3000, 10_000)
    per_state = []
    for k in chain:
        n, ms = measure(parse(f"F[0,{k}] p"), 10 * k)
        per_state.append(ms / (k + 3))
        rows.append(("chain", f"k={k}", n, ms))
    for n_events in (4, 8) if args.quick else (4, 8, 12, 16):
        spec = " & ".join(f"D[geometric(0.5)] e{i} & F(e{i} & F[0,3] A)"
                          for i in range(n_events))
        n, ms = measure(parse(spec), 1000)
        rows.append(("events", f"n={n_events}", n, ms))

    print(f"{'family':<14} {'parameters':<12} {'states':>18} {'ms':>10}")
    for name, params, n, ms in rows:
        print(f"{name:<14} {params:<12} {n:>18} {ms:>10.1f}")
    ratios = ", ".join(f"k={k}: {t / per_state[0]:.2f}" for k, t in zip(chain, per_state,
                                                                         strict=True))
    print(f"\nchain: time per state relative to k={chain[0]}: {ratios}")


if __name__ == "__main__":
    main()

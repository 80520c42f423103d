"""The automaton of the paper's example formula (Example 1, Fig. 1), drawn.

    phi = (D[mu1] b1 & F(b1 & F[0,3] b3)) | (D[mu2] b2 & F(b2 & F[0,3] b4))

with the paper's names (b1, b2 bus arrivals, external events; b3, b4 the robot at the
respective station) and the case-1 distributions.  Writes ``paper_dta.dot`` (one node per
automaton state: its location and clock valuation) and renders it to ``paper_dta.png``
with Graphviz's ``dot`` when it is on PATH.  Prints the size next to the paper's Fig. 1
(5 locations, 4 clocks) and where the difference in clocks comes from.

Run: ``python experiments/dta_figure.py [--quick] [--out DIR]`` (``--quick`` is the same:
the example is small).
"""

from __future__ import annotations

import shutil
import subprocess
import time
from dataclasses import dataclass

import _common as C

import mitld_lp
from mitld_lp.model import bind_distributions

SPEC = ("(D[geometric(0.8)] b1 & F(b1 & F[0,3] b3)) | "
        "(D[geometric(0.3)] b2 & F(b2 & F[0,3] b4))")
PAPER_LOCATIONS = 5  # Fig. 1: l_init, l1, l2, l4 and the accepting l3 (sink omitted)
PAPER_CLOCKS = 4  # c1, c2 (reset by b1, b2), c3, c4 (the deadlines after b1, b2)


@dataclass(frozen=True)
class Sizes:
    states: int
    locations: int
    clocks: int
    clock_names: tuple[str, ...]
    sta_clocks: int  # event clocks the STA keeps (clock reduction on)
    sta_clocks_paper: int  # ... and with clock_reduction=False (the paper's treatment)


def location_name(dta: mitld_lp.DTA, q: int) -> str:
    if dta.is_accepting(q):
        return "accept"
    if dta.is_rejecting(q):
        return "reject"
    return dta.location(q).obligation


def paper_names(dta: mitld_lp.DTA) -> dict[str, str]:
    """Our locations under the paper's names, found by stepping the DTA from its initial
    state on letters with the bus events (no station reached)."""
    q0 = dta.initial
    names = {location_name(dta, q0): "l_init"}
    for letter, paper in (({"b1"}, "l1"), ({"b2"}, "l2"), ({"b1", "b2"}, "l4")):
        names.setdefault(location_name(dta, dta.step(q0, letter)), paper)
    if dta.accepting is not None:
        names[location_name(dta, dta.accepting)] = "l3 (accepting)"
    if dta.rejecting is not None:
        names[location_name(dta, dta.rejecting)] = "sink (omitted in Fig. 1)"
    return names


def sizes(dta: mitld_lp.DTA, formula) -> Sizes:
    locations = {location_name(dta, q) for q in range(dta.n_states)}
    clock_names = sorted({name for q in range(dta.n_states) for name, _ in dta.clocks(q)})
    laws = bind_distributions(formula)
    sta = mitld_lp.make_sta(dta, laws, 0.01)
    sta_paper = mitld_lp.make_sta(dta, laws, 0.01, clock_reduction=False)

    def kept(s: mitld_lp.STA) -> int:
        return sum(c.cap > 0 or c.truncation is not None for c in s.clocks.values())

    return Sizes(dta.n_states, len(locations), len(clock_names), tuple(clock_names),
                 kept(sta), kept(sta_paper))


def main(argv: list[str] | None = None) -> Sizes:
    ap = C.parser(__doc__.splitlines()[0])
    args = ap.parse_args(argv)
    out = C.out_dir(args)
    start = time.perf_counter()
    formula = mitld_lp.parse(SPEC)
    dta = mitld_lp.to_dta(formula)
    s = sizes(dta, formula)

    print(f"The paper's example formula:\n  {SPEC}\n")
    print("Automaton states (location with its clock valuation):")
    for q in range(dta.n_states):
        text = "accept" if dta.is_accepting(q) else dta.location(q).label
        mark = " (initial)" if q == dta.initial else ""
        print(f"  q{q:<2} {text}{mark}")
    print("\nLocations (clock values removed), with the paper's names:")
    names = paper_names(dta)
    for loc in sorted({location_name(dta, q) for q in range(dta.n_states)},
                      key=lambda t: (t == "accept", t)):
        print(f"  {names.get(loc, '?'):<26} {loc}")
    header = ("", "paper's Fig. 1", "ours")
    rows = [["locations", PAPER_LOCATIONS, s.locations],
            ["clocks", PAPER_CLOCKS, s.clocks],
            ["(location, clock) states", "-", s.states]]
    print()
    print(C.text_table(header, rows))
    print(f"""
Clocks.  Ours are {' and '.join(s.clock_names)}: the paper's c3 and c4, one per
deadline operator, counting the steps since the bus came.  The paper's other two, c1
and c2, are the buses' ages for their distributions; they belong to the stochastic timed
automaton (STA) that attaches the distributions, not to the formula's automaton.  In our
STA all pending events share one step counter (every pending event's age is the current
step), and a memoryless (geometric) event needs none.  Buses clocked in our STA:
{s.sta_clocks} with clock reduction; {s.sta_clocks_paper} with clock_reduction=False (every
event truncated, as in the paper), sharing that one counter.
Our automaton also returns to l_init when a deadline is missed (the formula alone does
not know that a bus comes only once; the product with the pending set does), where
Fig. 1 omits its sink.""")

    dot_path = C.write_text(out / "paper_dta.dot", dta.to_dot())
    written = [C.shown(dot_path)]
    dot = shutil.which("dot")
    if dot:
        png = out / "paper_dta.png"
        subprocess.run([dot, "-Tpng", "-o", str(png), str(dot_path)], check=True,
                       capture_output=True, timeout=60)
        written.append(C.shown(png))
    else:
        print("\nNote: Graphviz's `dot` is not on PATH, so only the DOT file was written; "
              f"render it with `dot -Tpng -O {C.shown(dot_path)}`.")
    print(f"\nwrote {', '.join(written)} ({time.perf_counter() - start:.1f} s)")
    assert s.locations == PAPER_LOCATIONS, s
    return s


if __name__ == "__main__":
    main()

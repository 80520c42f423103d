"""Our property reader against Storm's, on every property of every QVBS PRISM model's
properties file: the same posed task (name, Storm's printing, spec, labels defined,
objective, comparison, threshold) or the same refusal, or declined to Storm's reader.

    python experiments/property_reader_check.py --qvbs <QVBS>          # every family
    python experiments/property_reader_check.py --qvbs <QVBS> --quick  # three families
    python experiments/property_reader_check.py --quick                # hand-written only

First the hand-written properties (``CASES``, on the program ``MODEL``), then each
QVBS properties file is read whole, then each of its properties alone (with the file's
``const`` lines), for the first model file of the family and the constants of its
first instance in ``index.json``.  Prints one line per difference and the counts;
writes ``property_reader_check.md`` into the output folder (``--out``; by default the
scratch folder ``experiments/out/quick``).
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common  # noqa: E402

QUICK_FAMILIES = ("csma", "consensus", "zeroconf")

#: A small program for the hand-written properties (every form the reader covers, and
#: forms it declines or Storm refuses).
MODEL = """mdp
const int N;
const int M = 3;
const int M2 = M*2;
const double p = 0.5;
const bool b = true;
const int D = N*2;
const double q;
const double r = q/2;
formula near = x > M2-2;
formula nearer = near & x < N;
formula odd = mod(x, 2) = 1;
module m
  x : [0..10] init 0;
  y : bool init false;
  [a] x < 10 -> p : (x'=x+1) + (1-p) : (y'=!y);
endmodule
label "goal" = x = 10;
label "two" = x=2 | y;
label "under_score" = y;
rewards "r" true : 1; endrewards
"""

CASES = [
    'Pmax=? [F "goal"]', 'Pmin=? [ F x=3 & y ]', 'P>=0.5 [ F<=M "goal" ]',
    'P>1/2 [ G !"two" ]', 'Pmax=? [ X x=1 ]', 'Pmax=? [ !"two" U x>=3 ]',
    'Pmax=? [ "two" U<=5 "goal" ]', 'Pmax=? [ F[2,N] "goal" ]', 'Pmax=? [ F<M+1 x=2 => y ]',
    'Pmax=? [F near]', 'Pmax=? [F nearer]', 'Pmax=? [F odd]', 'Pmax=? [F x+1 = 2*3 - (x/2)]',
    'Pmax=? [F (x=1|x=2)&!y]', 'filter(max, Pmax=? [F "goal"], "init")',
    'filter(min, Pmax=? [F y], "init")', 'filter(values, Pmax=? [F y], "init")',
    'filter(max, Pmax=? [F y], y)', 'filter(forall, P>=1 [F "goal"])',
    'Pmax=? [F "goal" | y]', 'Pmax=? [F !(x<=3)]', 'Pmax=? [F x!=3]', 'Pmax=? [F b]',
    'Pmax=? [F p > 0.3]', 'Pmax=? [F y <=> b]', 'Pmax=? [ F x=1 U y]', 'Pmax=? [F true]',
    'Pmax=? [F false]', 'Pmax=? [F "init"]', 'Pmax=? [F "deadlock"]', 'Pmax=? [F "nope"]',
    'Pmax=? [ F x = min(3,x)]', 'Pmax=? [F x = floor(2.5)]', 'Pmax=? [F y ? x=1 : x=2]',
    'Pmax=? [G<=3 y]', 'Pmax=? [ F>=3 y]', 'Pmax=? [F<=2.5 y]', 'P<=0.3 [F y]',
    'Pmax>=0.2 [F y]', 'Pmin<0.2 [F y]', 'P=? [F y]', 'Pmax=? [F (F y)]', 'Pmax=? [F y & F x=1]',
    'Pmax=? [F x=-1]', 'Pmax=? [F x = 1-2-3]', 'Pmax=? [F x = 12/4/3]', 'Pmax=?[F x^2=4]',
    'Pmax=? [F x mod 2 = 0]', 'Pmax=? [F !y]', 'Pmax=? [F x=1 & "goal"]',
    'Pmax=? [F "goal" & x=1 & y]', 'Pmax=? [F y & x=1 & "goal"]', 'Pmax=? [F !"goal"]',
    'Pmax=? [F !!"goal"]', 'Pmax=? [F !(x=1 & "goal")]', 'Pmax=? [F ("goal")]',
    'Pmax=? [F ((x=1))]', 'Pmax=? [F true & y]', 'Pmax=? [F "goal" => y]',
    'Pmax=? [F x=1.0]', 'Pmax=? [F x=N]', 'Pmax=? [ y U<=3 x=1]', 'Pmax=? [ y U[1,3] x=1]',
    'Pmax=? [ F<3 x=1]', 'Pmax=? [ F<1 x=1]', 'Pmax=? [ F<0 x=1]', 'Pmax=? [F x = 1e2]',
    'Pmax=? [F "goal" | "two" & y]', 'Pmax=? [F y | x=1 & "goal"]',
    'Pmax=? [F x=1 | y => "goal"]', 'Pmax=? [F !y U x=1]', 'Pmax=? [F y] // c',
    'Pmax=? [F x=2 = y]', 'Pmax=? [F x<3=y]', 'Pmax=? [X X y]', 'Pmax=? [F b & y]',
    'Pmax=? [F x=M2]', 'Pmax=? [F x=1 | y => x=2]', 'Pmax=? [F y => x=2 | x=1]',
    'Pmax=? [F y & y | y]', 'Pmax=? [F y | y & y]', 'Pmax=? [F !y & y]',
    'Pmax=? [F x+2*3-1 > 0]', 'Pmax=? [F -x < 0]', 'Pmax=? [F x = 2-(-1)]', 'Pmax=? [F zz]',
    'const int K;\n"a": Pmax=? [F x=K];\n"b": Pmin=? [F<=K y]',
    'const int K=2; Pmax=? [F x=K]; Pmax=? [F "goal"]', 'const int J; Pmax=? [F x=J]',
    '"a": Pmax=? [F y];\n"a": Pmin=? [F y]', 'Pmax=? [F x/2 = 1]', 'Pmax=? [F x*p = 1]',
    'Pmax=? [F y = true]', 'Pmax=? [(y) U (x=1)]', 'Pmax=? [F (y & "goal")]',
    'Pmax=? [F ("goal" & y) | y]', 'Pmax=? [ y U "goal" ]', 'Pmax=? [F (x=1)=y]',
    'Pmax=? [F 0.5 < p]', 'Pmax=? [F x = 0.25*4]', 'Pmax=? [ F<=0 y]', 'Pmax=? [ F[3,1] y]',
    'P>=0.9 [F y]', 'P>=1 [F y]', 'P<0 [F y]', 'P>=2 [F y]', 'P>=M/6 [F y]', 'P>N [F y]',
    'P>=p [F y]', 'Pmax=? [ F "goal" ]; Pmin=? [ G y ]', 'Pmax=? [ F "goal" ]\nPmin=? [ G y ]',
    'Pmax=? [F x=1 & y | x=2]', 'Pmax=? [F y | x=1 & x=2]', 'Pmax=? [F x=1 => y & y]',
    'Pmax=? [F 3 = x]', 'Pmax=? [F x > 2.5]', 'Pmax=? [F x - 1 > 2 + -1]',
    'Pmax=? [F (x)=1]', 'Pmax=? [F "goal" | !y]', 'Pmax=? [F !y | "goal"]',
    'Pmax=? [F !(y) | "goal"]', 'Pmax=? [F !(y | "goal")]', 'Pmax=? [F !(y | x=1)]',
    'Pmax=?[F(y)]', 'Pmax=? [ F<=M2 y]', 'Pmax=? [ F<=N y]', 'Pmax=? [ F<=1.5 y]',
    'Pmax=? [ F [ 1 , 2 ] y]', 'Pmax=? [ y U[0,M] x=1]', 'Pmin=? [ X "goal"]',
    'Pmax=? [ X !y]', 'Pmax=? [ G x<3 ]', 'Pmax=? [G "goal" & y]', 'Pmax=? [G !"goal" & y]',
    'Pmax=? [ !"goal" U<=3 !y]', 'Pmax=? [ "goal" & y U<=3 "goal"]', 'Pmax=? [F<=3 !"goal"]',
    'Pmax=? [F<=3 "goal" & y]', 'Pmax=? [X !"goal"]', 'Pmax=? [X "goal" | y]',
    'Pmax=? [F !(!"goal")]', 'Pmax=? [ y ]', 'Pmax=? [ "goal" ]', 'Pmax=? [F x]',
    'Pmax=? [F<=y "goal"]', 'Pmax=? [F "under_score"]', 'Pmax=? [F<=N+1 "goal"]',
    'R{"r"}min=? [F "goal"]', 'Rmin=? [F "goal"]', 'Tmin=? [F "goal"]', 'S=? ["goal"]',
    'Pmax=? [F{"r"}<=3 "goal"]', 'Pmax=? [F^{rew{"r"}<=3} "goal"]', 'multi(Pmax=? [F y], '
    'Pmax=? [F "goal"])', 'Pmax=? [F "goal" & F y]', 'Pmax=? [F Pmax>=1 [F y]]',
    'Pmax=? [y W "goal"]', 'Pmax=? [F "goal"', 'Pmax=? [F ]', 'Pmax=?', '', '// only',
    'P>=1 [F y]; R{"r"}min=? [F "goal"]', '/* c */ Pmax=? [F y]', 'Pmax=? [F y];;',
    'Pmax=? [F x=1 U<=2 y]', 'Pmax=? [F (x=1) U<=2 y]', 'Pmax=? [F y]\n\nPmin=? [F y]',
    'Pmax=? [F x=1.5e0 | y]', 'Pmax=? [F x >= -(2)]', 'Pmax=? [F !true]',
    'Pmax=? [F (true)]', 'Pmax=? [F x = .5]', 'const double K; Pmax=? [F x*K=1]',
    'const bool K; Pmax=? [F K]', 'const K = 2; Pmax=? [F x=K]', 'const int x = 2; Pmax=? [F y]',
    'Pmax=? [F x=D]', 'Pmax=? [F x*q < 1]', 'Pmax=? [F x*r < 1]', 'P>=q [F y]',
    'Pmax=? [F<=D y]', 'const double h; Pmax=? [F x*h < 1]', 'Pmax=? [\n F "goal"\n]',
    '"a":\nPmax=? [F "goal"]', 'Pmax = ? [F "goal"]', 'P >= 0.5 [F "goal"]',
    'Pmax=? [F "goal"]\n;Pmin=? [F y]', '  \n\n Pmax=? [F "goal"]\n\n', '"a b": Pmax=? [F y]',
    '"": Pmax=? [F y]', '"1": Pmax=? [F y]; Pmin=? [F y]', '"a-b": Pmax=? [F y]',
    '"_a1": Pmax=? [F y]', 'const int K = 2;\nconst double K2 = K/4;\nPmax=? [F x*K2 > 1]',
    'Pmax=? [F x>=1.5E1]', 'Pmax=? [F x=00]', 'Pmax=? [F x=2.50]', 'Pmax=? [X F "goal"]',
    'Pmax=? [F[0,0] "goal"]', 'Pmax=? [F<=0.0 "goal"]', 'Pmax=? [(x=1 | "goal") U y]',
    'Pmax=? [!(x=1) U !"goal"]', 'Pmin=? [G !(x=1 & y)]', 'P>=1 [G true]', 'P<=0 [F false]',
    'Pmax=? [F "goal" & true]', 'Pmax=? [F !(true)]', 'Pmax=? [F !x=1]', 'Pmax=? [F -x=-1]',
    'Pmax=? [F !y=y]', 'Pmax=? [F x=1=y]', 'Pmax=? [F x<1<2]', 'Pmax=? [F (y)=(y)]',
    'Pmax=? [F x = 3/6]', 'Pmax=? [F x = 1/3*3]',
]


def outcome(program: Any, text: str, constants: dict[str, Any], own: bool) -> list[Any]:
    """What the door makes of ``text``: per property its name and posed task, or that
    it is a reward query, or the refusal; or the reading's error."""
    from mitld_lp.worlds.prism_rewards import is_reward
    from mitld_lp.worlds.properties import (
        PropertyError,
        pick,
        pose_property,
        read_properties,
    )
    from mitld_lp.worlds.property_own import OwnProperty, read_any
    from mitld_lp.worlds.reward_bounded import is_reward_bounded

    try:
        props = (read_any(program, text, "P", constants) if own else
                 read_properties(program.program, text, "P", constants))
    except PropertyError as exc:
        return [("error", str(exc))]
    rows: list[Any] = []
    for name, prop in pick(props, None, "P"):
        ours = isinstance(prop, OwnProperty)
        if not ours and (is_reward(prop) or is_reward_bounded(prop)):
            rows.append((name, "reward"))
            continue
        try:
            q = pose_property(name, prop, program.labels, program.reserved,
                              chain=program.chain)
            rows.append((name, q.text, q.spec, tuple(q.define.items()), q.objective,
                         q.comparison, q.threshold))
        except PropertyError as exc:
            rows.append((name, "refused", str(exc)))
    return rows


def compare(model: Path, text: str, constants: dict[str, Any]) -> tuple[str, str]:
    """``(kind, detail)``: kind ``own`` (ours read it, the same), ``declined`` (Storm's
    reader read it), or ``DIFFERENT``; Storm's side reads the program with Storm,
    ours as the door does (our own parse's symbols where it takes the file)."""
    from mitld_lp.worlds.properties import read_program
    from mitld_lp.worlds.property_own import OwnProperty, read_any

    storm = outcome(read_program(str(model), storm=True), text, constants, own=False)
    # ours: the program as the door reads it (our own parse where it takes the file)
    program = read_program(str(model), constants)
    ours = outcome(program, text, constants, own=True)
    try:
        used = any(isinstance(p, OwnProperty)
                   for p in read_any(read_program(str(model), constants), text, "P",
                                     constants))
    except Exception:  # noqa: BLE001 - an error is compared above
        used = False
    if storm != ours:
        return "DIFFERENT", f"storm {storm}\n    ours  {ours}"
    return ("own" if used else "declined"), ""


def families(root: Path, quick: bool) -> list[tuple[str, Path, Path, dict[str, Any]]]:
    """``(family, model file, properties file, constants)`` of each family's first
    PRISM instance (and each of its properties files)."""
    out = []
    for index in sorted(root.glob("mdp/*/index.json")):
        folder = index.parent
        if quick and folder.name not in QUICK_FAMILIES:
            continue
        data = json.loads(index.read_text())
        seen: set[str] = set()
        for entry in data.get("files", []):
            original = entry.get("original-file") or []
            if isinstance(original, str):
                original = [original]
            models = [folder / f for f in original if Path(f).suffix in (".prism", ".nm",
                                                                         ".pm")]
            props = [folder / f for f in original if Path(f).suffix in (".props",
                                                                        ".prctl")]
            if not models or not props or not models[0].exists():
                continue
            if str(props[0]) in seen:
                continue
            seen.add(str(props[0]))
            values = {v["name"]: v["value"] for v in entry.get("file-parameter-values", [])}
            opened = entry.get("open-parameter-values") or [{}]
            values.update({v["name"]: v["value"] for v in opened[0].get("values", [])})
            out.append((folder.name, models[0], props[0], values))
    return out


def split(text: str) -> tuple[list[str], list[str]]:
    """A properties file's ``const`` lines and its properties, one text each."""
    consts, props = [], []
    for line in text.splitlines():
        bare = line.split("//")[0].strip()
        if not bare:
            continue
        if bare.startswith("const "):
            consts.append(bare)
        else:
            props.extend(p.strip() + ";" for p in bare.split(";") if p.strip())
    return consts, props


def hand_cases(out: Path) -> list[tuple[str, str]]:
    """``(case, kind)`` of every hand-written case (``DIFFERENT`` ones printed)."""
    model = out / "property_reader_model.prism"
    model.write_text(MODEL)
    rows = []
    for case in CASES:
        from mitld_lp.worlds.properties import parse_constants

        given = parse_constants("N=4,q=0.25,K=2,h=0.5")
        kind, detail = compare(model, case, given)
        rows.append((case.replace("\n", " / "), kind))
        if detail:
            print(f"{case!r}: DIFFERENT\n    {detail}")
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, default=None,
                    help="the QVBS benchmarks folder (without it: the hand-written cases)")
    args = ap.parse_args(argv)
    if args.out is None:  # a scratch folder, never the committed results
        args.out = _common.QUICK_OUT
    out = _common.out_dir(args)
    counts = {"own": 0, "declined": 0, "DIFFERENT": 0}
    rows = []
    for case, kind in hand_cases(out):
        counts[kind] += 1
        rows.append(("hand-written", "", case[:70], kind))
    qvbs = families(args.qvbs, args.quick) if args.qvbs is not None else []
    for family, model, props_file, values in qvbs:
        text = props_file.read_text()
        consts, props = split(text)
        from mitld_lp.worlds.properties import read_program

        program_constants = read_program(str(model)).constants
        given = {k: v for k, v in values.items()
                 if k in program_constants or re.search(rf"\bconst \w* ?{k}\b", text)}
        for label, piece in [("whole file", text)] + [(p, "\n".join(consts + [p]))
                                                     for p in props]:
            kind, detail = compare(model, piece, given)
            counts[kind] += 1
            rows.append((family, props_file.name, label[:70], kind))
            if detail:
                print(f"{family} {props_file.name} {label}: DIFFERENT\n    {detail}")
    header = ("family", "file", "property", "outcome")
    print(_common.text_table(header, rows))
    print(f"own {counts['own']}, declined {counts['declined']}, different "
          f"{counts['DIFFERENT']}")
    escaped = [[str(c).replace("|", "\\|") for c in row] for row in rows]
    _common.write_text(out / "property_reader_check.md",
                       _common.markdown_table(header, escaped) +
                       f"\nown {counts['own']}, declined {counts['declined']}, "
                       f"different {counts['DIFFERENT']}\n")
    return 1 if counts["DIFFERENT"] else 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Our property reader against Storm's, on every property of every QVBS PRISM model's
properties file: the same posed task (name, Storm's printing, spec, labels defined,
objective, comparison, threshold) or the same refusal, or declined to Storm's reader.

    python experiments/property_reader_check.py --qvbs <QVBS>          # every family
    python experiments/property_reader_check.py --qvbs <QVBS> --quick  # three families

Each properties file is read whole, then each of its properties alone (with the file's
``const`` lines), for the first model file of the family and the constants of its
first instance in ``index.json``.  Prints one line per difference and the counts;
writes ``property_reader_check.md`` into the output folder.
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
    reader read it), or ``DIFFERENT``."""
    from mitld_lp.worlds.properties import read_program
    from mitld_lp.worlds.property_own import OwnProperty, read_any

    storm = outcome(read_program(str(model)), text, constants, own=False)
    program = read_program(str(model))  # Storm's reader adds the file's constants to it
    ours = outcome(program, text, constants, own=True)
    try:
        used = any(isinstance(p, OwnProperty)
                   for p in read_any(read_program(str(model)), text, "P", constants))
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


def main(argv: list[str] | None = None) -> int:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, required=True, help="the QVBS benchmarks folder")
    args = ap.parse_args(argv)
    out = _common.out_dir(args)
    counts = {"own": 0, "declined": 0, "DIFFERENT": 0}
    rows = []
    for family, model, props_file, values in families(args.qvbs, args.quick):
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
    _common.write_text(out / "property_reader_check.md",
                       _common.markdown_table(header, rows) +
                       f"\nown {counts['own']}, declined {counts['declined']}, "
                       f"different {counts['DIFFERENT']}\n")
    return 1 if counts["DIFFERENT"] else 0


if __name__ == "__main__":
    raise SystemExit(main())

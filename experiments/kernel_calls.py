"""Which (kernel, argument types) pairs the routes call: what ``mitld-lp warm`` must compile.

Runs a command (a benchmark of this repository, whose children inherit the environment)
with a ``sitecustomize`` that records, in every Python process it starts, each compiled
kernel's call as :func:`mitld_lp.util.warm_kernels.record` does, and merges the records
into ``kernel_calls.json`` of ``--out``; ``--force`` forces the compiled gates on (every
kernel counted as cached, its load as paid), ``--cache DIR`` sets ``NUMBA_CACHE_DIR``
(default: a fresh folder, so numba compiles what is called).  Then prints the pairs not
in :data:`mitld_lp.util.warm_kernels.SIGNATURES` (``--table``: all of them, as that
literal)::

    python experiments/kernel_calls.py --force -- python experiments/bench_qvbs.py \
        --qvbs <QVBS> --min-states 0 --only consensus.4-4.c2 --out /tmp/q
    python experiments/kernel_calls.py --table   # the merged records as the literal
    python experiments/kernel_calls.py --quick   # the bundled case's solve alone

Records accumulate in ``--out`` across runs (``--fresh`` empties it first).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from mitld_lp.util import warm_kernels  # noqa: E402

HOOK = """\
import atexit, json, os
from mitld_lp.util import warm_kernels
_seen = warm_kernels.record(os.environ.get("KERNEL_CALLS_FORCE") == "1")
def _dump():
    with open(os.path.join(os.environ["KERNEL_CALLS_DIR"], f"{os.getpid()}.json"), "w") as f:
        json.dump(sorted(_seen), f)
atexit.register(_dump)
"""

QUICK = [sys.executable, "-m", "mitld_lp", "solve", "models/bus_grid.toml"]


def run(command: list[str], out: Path, force: bool, cache: Path | None) -> int:
    """``command`` with the recording hook; its exit status."""
    calls = out / "calls"
    calls.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="kernel-calls-") as tmp:
        Path(tmp, "sitecustomize.py").write_text(HOOK, encoding="utf-8")
        env = dict(os.environ, KERNEL_CALLS_DIR=str(calls), KERNEL_CALLS_FORCE=str(int(force)))
        env["PYTHONPATH"] = os.pathsep.join([tmp, str(ROOT), *filter(None, [
            env.get("PYTHONPATH")])])
        if cache is not None:
            env["NUMBA_CACHE_DIR"] = str(cache)
        return subprocess.run(command, cwd=ROOT, env=env).returncode


def merged(out: Path) -> dict[str, dict[str, set[str]]]:
    """Every recorded pair: module -> kernel -> encoded types."""
    found: dict[str, dict[str, set[str]]] = {}
    for f in sorted((out / "calls").glob("*.json")):
        for module, name, key in json.loads(f.read_text(encoding="utf-8")):
            found.setdefault(module, {}).setdefault(name, set()).add(key)
    return found


def literal(found: dict[str, dict[str, set[str]]]) -> str:
    """``found`` with the listed signatures as the :data:`SIGNATURES` literal (lines
    within 100 characters: a long signature in pieces, each ending at a word)."""
    both = {m: {k: set(v) for k, v in ks.items()} for m, ks in found.items()}
    for module, name, key in warm_kernels.signatures():
        both.setdefault(module, {}).setdefault(name, set()).add(warm_kernels.encode(key))
    lines = ["SIGNATURES: dict[str, dict[str, tuple[str, ...]]] = {"]
    for module in sorted(both):
        lines.append(f'    "{module}": {{')
        for name in sorted(both[module]):
            keys = sorted(k for k in both[module][name] if k != "?")
            if keys:
                lines.append(f'        "{name}": (')
                for key in keys:
                    lines += _pieces(key)
                lines.append("        ),")
        lines.append("    },")
    lines.append("}")
    return "\n".join(lines)


def _pieces(key: str, width: int = 84) -> list[str]:
    out, piece = [], ""
    for word in key.split(" "):
        if piece and len(piece) + len(word) + 1 > width:
            out.append(f'            "{piece} "')
            piece = word
        else:
            piece = f"{piece} {word}" if piece else word
    out.append(f'            "{piece}",')
    return out


def missing(found: dict[str, dict[str, set[str]]]) -> list[str]:
    listed = {(m, n, warm_kernels.encode(k)) for m, n, k in warm_kernels.signatures()}
    return [f"{m}.{n}({k})" for m, ks in sorted(found.items()) for n, keys in sorted(ks.items())
            for k in sorted(keys) if (m, n, k) not in listed]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "experiments" / "out" / "kernel_calls")
    ap.add_argument("--force", action="store_true", help="the compiled gates forced on")
    ap.add_argument("--cache", type=Path, default=None, help="NUMBA_CACHE_DIR (default fresh)")
    ap.add_argument("--fresh", action="store_true", help="forget earlier records in --out")
    ap.add_argument("--table", action="store_true", help="print the SIGNATURES literal")
    ap.add_argument("--quick", action="store_true", help="the bundled case's solve alone")
    ap.add_argument("command", nargs="*", help="the command to record (after --)")
    args = ap.parse_args(argv)
    if args.fresh:
        for f in (args.out / "calls").glob("*.json"):
            f.unlink()
    command = QUICK if args.quick else args.command
    status = 0
    if command:
        with tempfile.TemporaryDirectory(prefix="kernel-calls-cache-") as fresh:
            status = run(command, args.out, args.force, args.cache or Path(fresh))
    found = merged(args.out)
    if args.table:
        print(literal(found))
    gone = missing(found)
    unkeyed = [g for g in gone if g.endswith("(?)")]
    print(f"{sum(len(v) for ks in found.values() for v in ks.values())} pairs recorded "
          f"({args.out}); not listed: {len(gone) - len(unkeyed)}; calls the loader does "
          f"not key: {len(unkeyed)}")
    for line in gone:
        print("  " + line)
    return status


if __name__ == "__main__":
    sys.exit(main())

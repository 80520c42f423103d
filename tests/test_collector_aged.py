"""The collector put back on after the package's imports (:mod:`mitld_lp.util.collector`):
what the imports made is in the oldest generation, nothing is frozen, a program's own
frozen objects stay frozen, and a garbage cycle made before the import is still
collected by a full collection.  Each in a fresh interpreter (the collector's state
is the point); the expected generations are the collector's own ``gc.get_objects``."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: argv[1]: "frozen" to freeze some of the program's objects before the import.
PROBE = r"""
import gc, json, sys, weakref
class Node:
    pass
if sys.argv[1] == "frozen":
    kept = [[i] for i in range(100)]
    gc.freeze()
a, b = Node(), Node()
a.other, b.other = b, a  # a garbage cycle once the names go
gone = weakref.ref(a)
del a, b
frozen_before = gc.get_freeze_count()
from mitld_lp import load_model  # the package's imports (the window opens and closes)
import mitld_lp.model as made
by_generation = [set(map(id, gc.get_objects(generation=g))) for g in range(3)]
where = [g for g in range(3) if id(made.Model) in by_generation[g]]
frozen_after = gc.get_freeze_count()
alive_before_full = gone() is not None
gc.collect()
print(json.dumps(dict(where=where, frozen_before=frozen_before, frozen_after=frozen_after,
                      enabled=gc.isenabled(), alive_before_full=alive_before_full,
                      collected=gone() is None)))
"""


def _run(mode: str, code: str = PROBE) -> dict:
    """``code`` in a fresh interpreter with ``mode`` as its argument: its last line's JSON."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONDONTWRITEBYTECODE", "MITLD_LP_PLAIN_IMPORTS")}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    done = subprocess.run([sys.executable, "-c", code, mode], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_the_imports_objects_are_aged_and_nothing_is_frozen() -> None:
    got = _run("plain")
    assert got["enabled"] is True and got["frozen_before"] == got["frozen_after"] == 0
    assert got["where"] == [2]  # the package's class, made by its import: oldest generation
    # the program's cycle made before the import aged too: a full collection takes it
    assert got["collected"] is True


def test_a_programs_frozen_objects_stay_frozen() -> None:
    got = _run("frozen")
    assert got["frozen_before"] > 0
    assert got["frozen_after"] == got["frozen_before"]  # not given back to the collector
    assert got["enabled"] is True and got["collected"] is True


#: How often ``release`` asks ``gc.get_freeze_count`` (a walk over every frozen object):
#: never after ``leave_frozen``; with the program's objects frozen, once and then never.
COUNTS = r"""
import gc, json, sys
from mitld_lp.util import collector
asked = [0]
count = gc.get_freeze_count
def counted():
    asked[0] += 1
    return count()
gc.get_freeze_count = counted
if sys.argv[1] == "command":
    gc.freeze()
    collector.leave_frozen()
else:
    kept = [[i] for i in range(100)]
    gc.freeze()
for _ in range(3):
    gc.disable()
    collector.release()
print(json.dumps(dict(asked=asked[0], enabled=gc.isenabled(), frozen=count() > 0)))
"""


def test_the_frozen_count_is_not_walked_once_objects_are_frozen() -> None:
    assert _run("command", COUNTS) == dict(asked=0, enabled=True, frozen=True)
    assert _run("program", COUNTS) == dict(asked=1, enabled=True, frozen=True)

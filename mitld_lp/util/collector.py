"""The garbage collector put back on after the package's imports, their objects aged.

The package's imports run with Python's cyclic collector held
(:mod:`mitld_lp.own_imports`).  Put back on plainly, the collector would then pass over
every object those imports made (modules, functions, classes, SciPy's, lark's and
stormpy's among them: some 30,000) twice before they settle: once in the first young
collection after the imports (the allocation count is already past its threshold) and
once more in the middle generation.  Those passes find nothing (an import makes no
garbage cycle worth collecting) and cost the PRISM route 10-15 ms of CPU in its load,
measured with ``gc.callbacks``.

:func:`release` puts the collector back on with those objects moved to the oldest
generation first (``gc.freeze()`` then ``gc.unfreeze()``: two list splices, no pass),
where a full collection still examines them, as it examines the program's own old
objects.  Nothing is left frozen, and nothing is moved where the program has frozen
objects of its own (``gc.unfreeze`` would give them back to the collector); then the
collector is only put back on.  No answer depends on when a cycle is collected; the
program's young objects made before the import age with the rest (collected, if
garbage, at the next full collection instead of the next young one).

``gc.get_freeze_count()`` walks the frozen objects one by one (CPython 3.11: 56,000 of
them after the command line's own freeze, 2-5 ms a call on a busy machine), so it is
asked only until it first answers more than 0, and not at all once the command line
has frozen its imports (:func:`leave_frozen`): from then on the collector is only put
back on.
"""

from __future__ import annotations

import gc

__all__ = ["leave_frozen", "release"]

_aging = [True]  # whether release may still age the objects (nothing frozen seen yet)


def release() -> None:
    """The collector back on, what exists now in its oldest generation (module docs)."""
    if _aging[0]:
        if gc.get_freeze_count() == 0:  # (quick while nothing is frozen)
            gc.freeze()
            gc.unfreeze()
        else:  # the program keeps objects frozen: left so, and not asked again
            _aging[0] = False
    gc.enable()


def leave_frozen() -> None:
    """Objects are frozen now and stay so (the command line's start, which froze the
    imported modules): :func:`release` only puts the collector back on."""
    _aging[0] = False

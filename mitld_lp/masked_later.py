"""NumPy's masked arrays (``numpy.ma``) left for later when the package's own
``np.unique`` is what imports them: the module is there, its body runs at its first use.

``np.unique(values)`` (NumPy 2) asks ``np.ma.is_masked(values)`` before its hash-based
path, which imports ``numpy.ma`` (7-12 ms of CPU) in the first call of a process, for a
plain array whose answer is False: a plain ``numpy.ndarray`` has no mask.  The command
line puts the whole module off (:func:`mitld_lp.startup.numpy_ma_when_used`); a program
that imports the package gets, through :mod:`mitld_lp.own_imports`'s finder, this
narrower cut: when the import of ``numpy.ma`` comes from NumPy's ``unique`` called by
the package's code (:func:`asked_by_unique`), the module is made by the import system as
always (in ``sys.modules``, bound as ``numpy.ma``, the same object for good) but its
``__init__`` has not run (:class:`MaskedLater`).  The first name anybody else reads, or
``dir``, runs it in that same module, which is then the plain module the import system
makes: a program sees ``numpy.ma``'s own objects, each time.  NumPy's ``unique`` alone
(the reading frame's module is :data:`UNIQUE_MODULE`) is answered ``is_masked`` by
:func:`plain_is_masked` while the body has not run: False for an exact
``numpy.ndarray`` (``numpy.ma.is_masked``'s own answer: ``getmask`` of it is
``nomask``), the real function's answer for anything else.
"""

from __future__ import annotations

import sys
import threading
import types
from typing import Any

__all__ = ["NUMPY_MA", "UNIQUE_MODULE", "MaskedLater", "asked_by_unique", "made_later",
           "plain_is_masked"]

#: The package whose modules' ``np.unique`` get ``numpy.ma`` later (not imported from
#: :mod:`mitld_lp.own_imports`, which imports this module: no circle).
PACKAGE = __name__.partition(".")[0]

#: The module put off.
NUMPY_MA = "numpy.ma"

#: NumPy's module whose ``unique`` asks ``np.ma.is_masked`` (NumPy 2).
UNIQUE_MODULE = "numpy.lib._arraysetops_impl"

_lock = threading.RLock()  # the body's run: another thread's first use waits for it
_running: list[int] = []  # the thread running the body, while it runs


def asked_by_unique() -> bool:
    """Whether the import of ``numpy.ma`` under way comes from NumPy's ``__getattr__``
    serving ``np.ma`` to NumPy's ``unique``, itself called (through NumPy's own
    functions only) by one of the package's modules."""
    frame = sys._getframe(1)
    while frame is not None and str(frame.f_globals.get("__name__")) in (
            __name__, f"{PACKAGE}.own_imports", "importlib._bootstrap",
            "importlib._bootstrap_external", "_frozen_importlib",
            "_frozen_importlib_external"):
        frame = frame.f_back  # the finder's frames and the import system's
    if frame is None or frame.f_globals.get("__name__") != "numpy" or \
            frame.f_code.co_name != "__getattr__":
        return False
    frame = frame.f_back
    if frame is None or frame.f_globals.get("__name__") != UNIQUE_MODULE:
        return False
    while frame is not None:
        name = frame.f_globals.get("__name__", "")
        if not isinstance(name, str):
            return False
        if name != "numpy" and not name.startswith("numpy."):
            return name.startswith(PACKAGE + ".")
        frame = frame.f_back
    return False


def plain_is_masked(x: object) -> Any:
    """``numpy.ma.is_masked(x)``: False for an exact ``numpy.ndarray``, else the real
    function's answer (the body run first)."""
    import numpy

    if type(x) is numpy.ndarray:
        return False
    return sys.modules[NUMPY_MA].is_masked(x)


class MaskedLater(types.ModuleType):
    """``numpy.ma`` whose ``__init__`` has not run (module docs): like
    :class:`mitld_lp.own_imports.BodyLater`, with its own lock and one name served."""

    def _load(self) -> None:
        with _lock:
            if type(self) is not MaskedLater or _running:
                return  # run by now, or being run by this thread (the lock is ours)
            _running.append(threading.get_ident())
            try:
                vars(self)["__spec__"].loader.exec_module(self)
            finally:
                self.__class__ = types.ModuleType  # no more stand-in, whatever happened
                _running.clear()

    def __getattr__(self, name: str) -> Any:
        if (name == "is_masked" and not _running
                and sys._getframe(1).f_globals.get("__name__") == UNIQUE_MODULE):
            return plain_is_masked
        if _running and _running[0] == threading.get_ident():
            raise AttributeError(f"partially initialized module {NUMPY_MA!r} has no "
                                 f"attribute {name!r}")
        self._load()
        return getattr(self, name)

    def __dir__(self) -> list[str]:
        self._load()
        return dir(self)


def made_later(_loader: Any, module: types.ModuleType) -> None:
    """The import of ``numpy.ma`` (:func:`asked_by_unique`): the module the import
    system made becomes a :class:`MaskedLater` (:class:`mitld_lp.own_imports.BodyLaterLoader`
    runs this instead of the body)."""
    module.__class__ = MaskedLater

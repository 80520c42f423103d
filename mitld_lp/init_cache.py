"""The command line's dataclass ``__init__`` methods compiled once, not once a process.

Python 3.11 and 3.12 write each dataclass's ``__init__`` as source text and compile it
(``dataclasses._create_fn``): the bundled case's command makes 97 dataclasses while it
runs, and compiling their ``__init__`` methods is 0.035 s of its 0.55 s of CPU (the
other generated methods are closures already,
:mod:`mitld_lp.dataclass_closures`). Here ``_create_fn`` takes the
code object compiled from the same text from a table kept beside the package's bytecode
(``mitld_lp/__pycache__/dataclass_inits.<tag>.marshal``), compiling only a text the
table lacks; the table gets the new texts when the process ends (unless Python writes no
bytecode either: ``-B``, ``PYTHONDONTWRITEBYTECODE``). The code is the compiler's own
output for the same text, file name ``<string>``, run with the same globals and locals:
the method is the one ``exec`` of the text makes.

The table is trusted as the ``.pyc`` files beside it are; it is keyed by the whole
source text and carries the interpreter's bytecode magic number (another Python ignores
it).  A table that cannot be read is ignored, and one that cannot be written (a
read-only installation) is not written: the methods are then compiled as before.
"""

from __future__ import annotations

import marshal
import os
import sys
from types import CodeType
from typing import Any

__all__ = ["MAX_ENTRIES", "install", "table_path"]

#: At most this many texts are kept (the package's dataclasses are about 300).
MAX_ENTRIES = 4096

#: The source texts compiled by this process, the code of each.
_codes: dict[str, CodeType] = {}
#: The texts compiled in this process that the table on disk lacked.
_new: list[str] = []


def _magic() -> bytes:
    from importlib.util import MAGIC_NUMBER

    return MAGIC_NUMBER


def table_path() -> str:
    """Where the table is kept: beside the package's bytecode, one per interpreter."""
    return os.path.join(os.path.dirname(os.path.abspath(__file__)), "__pycache__",
                        f"dataclass_inits.{sys.implementation.cache_tag}.marshal")


def _read(path: str) -> dict[str, CodeType]:
    """The table at ``path``; empty if it is missing, of another Python or damaged."""
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError:
        return {}
    magic = _magic()
    if not data.startswith(magic):
        return {}
    try:
        table = marshal.loads(data[len(magic):])
    except (EOFError, ValueError, TypeError):
        return {}
    if not isinstance(table, dict):
        return {}
    return {k: v for k, v in table.items() if isinstance(k, str) and isinstance(v, CodeType)}


def _write(path: str) -> None:
    """Add this process's new texts to the table on disk (read again: another process
    may have written it meanwhile), replaced in one step; nothing if it cannot be."""
    if not _new:
        return
    table = _read(path)
    for text in _new:
        table[text] = _codes[text]
    if len(table) > MAX_ENTRIES:  # the oldest go first (dicts keep their order)
        table = dict(list(table.items())[-MAX_ENTRIES:])
    tmp = f"{path}.{os.getpid()}.tmp"
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(tmp, "wb") as fh:
            fh.write(_magic() + marshal.dumps(table))
        os.replace(tmp, path)
    except OSError:
        try:
            os.remove(tmp)
        except OSError:
            pass
    _new.clear()


def _code(text: str) -> CodeType:
    code = _codes.get(text)
    if code is None:
        code = compile(text, "<string>", "exec")  # what ``exec(text)`` compiles
        _codes[text] = code
        _new.append(text)
    return code


#: Whether every dataclass's ``__init__`` comes from the table (the command line), or
#: only the package's own (a program importing the package); None: not installed.
_for_all: bool | None = None
#: The ``_create_fn`` installed (None: not installed).
_installed: Any = None


def install(package_only: bool = False) -> bool:
    """Have ``dataclasses._create_fn`` take its code from the table (loaded now, written
    at exit); False (nothing done) on a Python whose ``_create_fn`` is not the one
    replaced here.  ``package_only`` (a program importing the package,
    :mod:`mitld_lp.library_start`): only for the package's own dataclasses, every other
    class's methods compiled by dataclasses itself; a later call without it widens the
    table to every class."""
    global _for_all, _installed
    import atexit
    import dataclasses
    import inspect

    from mitld_lp.dataclass_closures import in_package

    if sys.version_info[:2] not in ((3, 11), (3, 12)):
        return False
    if _for_all is not None:  # installed already: the scope is all that changes
        _for_all = _for_all or not package_only
        if _installed is not None:  # (back in place if the stdlib's was put back)
            dataclasses._create_fn = _installed
        return True
    original = getattr(dataclasses, "_create_fn", None)
    try:
        params = list(inspect.signature(original).parameters) if original else []
    except (TypeError, ValueError):
        return False
    if params != ["name", "args", "body", "globals", "locals", "return_type"]:
        return False
    missing = dataclasses.MISSING
    path = table_path()
    _codes.update(_read(path))

    def _create_fn(name: str, args: list[str], body: list[str], *,
                   globals: dict | None = None, locals: dict | None = None,
                   return_type: Any = missing) -> Any:
        if not (_for_all or in_package(globals)):
            return original(name, args, body, globals=globals, locals=locals,
                            return_type=return_type)
        # dataclasses' own text, line for line (3.11, 3.12)
        if locals is None:
            locals = {}
        return_annotation = ""
        if return_type is not missing:
            locals["_return_type"] = return_type
            return_annotation = "->_return_type"
        args_text = ",".join(args)
        body_text = "\n".join(f"  {b}" for b in body)
        txt = f" def {name}({args_text}){return_annotation}:\n{body_text}"
        local_vars = ", ".join(locals.keys())
        txt = f"def __create_fn__({local_vars}):\n{txt}\n return {name}"
        ns: dict[str, Any] = {}
        exec(_code(txt), globals, ns)
        return ns["__create_fn__"](**locals)

    _for_all = not package_only
    _installed = dataclasses._create_fn = _create_fn
    if not sys.dont_write_bytecode:  # ``-B``, PYTHONDONTWRITEBYTECODE: read it only
        atexit.register(_write, path)
    return True

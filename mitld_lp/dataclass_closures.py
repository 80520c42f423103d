"""Dataclass methods made as closures instead of source compiled with ``exec``.

:func:`mitld_lp.startup.dataclass_methods_without_exec` (the command line, every
class) and :mod:`mitld_lp.library_start` (a program importing the package, the
package's classes only) call :func:`methods_without_exec`; :mod:`mitld_lp.init_cache` asks
:func:`in_package` which classes are the package's.
"""

from __future__ import annotations

import sys

TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Callable
    from dataclasses import Field
    from typing import Any

__all__ = ["DATACLASS_PYTHONS", "in_package", "methods_without_exec"]


#: The Pythons whose ``dataclasses`` make the methods below with these functions, each
#: compiling its method's source (3.13 compiles a class's methods at once).
DATACLASS_PYTHONS = ((3, 11), (3, 12))
_DATACLASS_MAKERS = ("_repr_fn", "_cmp_fn", "_hash_fn", "_frozen_get_del_attr",
                     "_recursive_repr", "FrozenInstanceError")


def methods_without_exec(package_only: bool = False) -> None:
    """Have :func:`dataclasses.dataclass` make ``__repr__``, ``__eq__`` (and the order),
    ``__hash__`` and a frozen class's ``__setattr__`` and ``__delattr__`` as closures
    over the field names instead of compiling each method's source with ``exec``.

    Python 3.11 and 3.12 write every such method as text and compile it: 0.2 ms of CPU
    each, six for a frozen record with equality, so about 1 ms a class, while its
    ``__init__`` (kept compiled: its signature and speed matter) is one of the six.
    The bundled case's command makes 118 dataclasses, 113 frozen (formula nodes,
    automata, product tables, the routes' and solvers' records): about 0.09 s of its
    CPU, 0.045 s with the closures.  The closures do what the compiled methods do,
    operation for operation: ``__eq__`` and the order compare the tuples of the
    compared fields when both are of the same class (else ``NotImplemented``),
    ``__hash__`` hashes that tuple (the same number, so sets of records iterate in the
    same order), ``__repr__`` writes the same text (through dataclasses' own guard
    against recursion), and a frozen class refuses an assignment or a deletion with the
    same :class:`dataclasses.FrozenInstanceError`.

    The command line makes every class's methods so; a program importing the package
    only the package's own (``package_only``, :mod:`mitld_lp.library_start`): a class
    of another module gets the stdlib's methods.  A later call without
    ``package_only`` widens it to every class.  Nothing on another Python (3.13
    compiles a class's methods in one go) or if the module's makers are not the ones
    replaced here."""
    global _closures_for_all
    import dataclasses

    if (sys.version_info[:2] not in DATACLASS_PYTHONS
            or not all(hasattr(dataclasses, name) for name in _DATACLASS_MAKERS)):
        return
    _closures_for_all = _closures_for_all or not package_only
    if getattr(dataclasses._repr_fn, "__module__", None) == __name__:
        return  # installed already: the scope is all that changes
    for name, maker in (("_repr_fn", _repr_fn), ("_cmp_fn", _cmp_fn), ("_hash_fn", _hash_fn),
                        ("_frozen_get_del_attr", _frozen_get_del_attr)):
        setattr(dataclasses, name, _chosen(maker, getattr(dataclasses, name)))


#: Whether every dataclass gets the closures (the command line), or only the package's.
_closures_for_all = False


def in_package(globals: dict | None) -> bool:
    """Whether a dataclass made with the module globals ``globals`` is one of the
    package's own (its module is ``mitld_lp`` or below it)."""
    name = (globals or {}).get("__name__", "")
    return isinstance(name, str) and name.partition(".")[0] == "mitld_lp"


def _chosen(closures: Callable[..., Any], stdlib: Callable[..., Any]) -> Callable[..., Any]:
    """The maker dataclasses calls: ``closures`` for the classes in scope
    (:data:`_closures_for_all`, else the package's own), ``stdlib`` for the others.
    Its ``globals`` argument (the class's module's), last, is positional or named."""

    def maker(*args: Any, **kwargs: Any) -> Any:
        globals = kwargs["globals"] if "globals" in kwargs else args[-1]
        if _closures_for_all or in_package(globals):
            return closures(*args, **kwargs)
        return stdlib(*args, **kwargs)

    maker.__name__ = maker.__qualname__ = closures.__name__
    return maker


def _tuple_of(names: tuple[str, ...]) -> Callable[[object], tuple]:
    """The function giving ``(obj.a, obj.b, ...)`` for the field names ``names``, as
    dataclasses' source writes it (a tuple also for one field or none)."""
    from operator import attrgetter

    if len(names) > 1:
        return attrgetter(*names)  # a tuple already
    if names:
        get = attrgetter(names[0])
        return lambda obj: (get(obj),)
    return lambda obj: ()


def _named(fn: Callable[..., Any], name: str, globals: dict) -> Callable[..., Any]:
    """``fn`` named as dataclasses names the method, of the class's module."""
    fn.__name__ = fn.__qualname__ = name
    fn.__module__ = globals.get("__name__", fn.__module__)
    return fn


def _repr_fn(fields: list[Field], globals: dict) -> Callable[..., Any]:
    import dataclasses

    names = tuple(f.name for f in fields)

    def __repr__(self: object) -> str:
        return (self.__class__.__qualname__ + "("
                + ", ".join([f"{name}={getattr(self, name)!r}" for name in names]) + ")")

    return dataclasses._recursive_repr(_named(__repr__, "__repr__", globals))


#: The comparisons dataclasses writes (``op`` of ``_cmp_fn``).
_COMPARISONS = {"==": "eq", "<": "lt", "<=": "le", ">": "gt", ">=": "ge"}


def _cmp_fn(name: str, op: str, self_tuple: str, other_tuple: str,
            globals: dict) -> Callable[..., Any]:
    import operator

    # self_tuple is dataclasses' source of the tuple: "()" or "(self.a,self.b,)"
    names = tuple(part.split(".", 1)[1] for part in self_tuple[1:-1].split(",") if part)
    values = _tuple_of(names)
    if op == "==" and len(names) == 1:  # the common cases without a call more than needed
        get = operator.attrgetter(names[0])

        def method(self: object, other: object) -> Any:
            if other.__class__ is self.__class__:
                return (get(self),) == (get(other),)
            return NotImplemented
    elif op == "==":
        def method(self: object, other: object) -> Any:
            if other.__class__ is self.__class__:
                return values(self) == values(other)
            return NotImplemented
    else:
        compare = getattr(operator, _COMPARISONS[op])

        def method(self: object, other: object) -> Any:
            if other.__class__ is self.__class__:
                return compare(values(self), values(other))
            return NotImplemented

    return _named(method, name, globals)


def _hash_fn(fields: list[Field], globals: dict) -> Callable[..., Any]:
    from operator import attrgetter

    names = tuple(f.name for f in fields)
    if len(names) == 1:
        get = attrgetter(names[0])

        def __hash__(self: object) -> int:
            return hash((get(self),))
    else:
        values = _tuple_of(names)

        def __hash__(self: object) -> int:
            return hash(values(self))

    return _named(__hash__, "__hash__", globals)


def _frozen_get_del_attr(cls: type, fields: list[Field],
                         globals: dict) -> tuple[Callable[..., Any], ...]:
    from dataclasses import FrozenInstanceError

    names = tuple(f.name for f in fields)

    def __setattr__(self: object, name: str, value: object) -> None:
        if type(self) is cls or name in names:
            raise FrozenInstanceError(f"cannot assign to field {name!r}")
        super(cls, self).__setattr__(name, value)

    def __delattr__(self: object, name: str) -> None:
        if type(self) is cls or name in names:
            raise FrozenInstanceError(f"cannot delete field {name!r}")
        super(cls, self).__delattr__(name)

    return (_named(__setattr__, "__setattr__", globals),
            _named(__delattr__, "__delattr__", globals))

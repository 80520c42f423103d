"""MITLD formulas: the AST, the parser, the supported fragment and reference evaluators.

The reference evaluators (:mod:`.semantics`: ``holds``, ``holds_lasso``, ``Verdict``) are
imported on first use: a solve reads formulas but never evaluates one on a word."""

import importlib
from typing import TYPE_CHECKING, Any

from mitld_lp.logic.fragment import (
    FragmentError,
    FragmentReport,
    check,
    classify,
    event_distributions,
    horizon,
    is_co_safe,
    nnf,
)
from mitld_lp.logic.parser import ParseError, parse, parse_distribution, parse_source
from mitld_lp.logic.source import LawSite, Source
from mitld_lp.logic.syntax import (
    FALSE,
    TRUE,
    And,
    Const,
    Dist,
    DistLiteral,
    DistRef,
    DistSpec,
    Formula,
    Interval,
    Next,
    Not,
    Or,
    Prop,
    Release,
    Until,
    always,
    atoms,
    conj,
    disj,
    dist,
    eventually,
    implies,
    neg,
    nxt,
    release,
    subformulas,
    until,
    weak,
)

if TYPE_CHECKING:
    from mitld_lp.logic.semantics import Verdict, holds, holds_lasso

_LAZY = {"holds": "mitld_lp.logic.semantics", "holds_lasso": "mitld_lp.logic.semantics",
         "Verdict": "mitld_lp.logic.semantics"}

__all__ = [
    "parse",
    "parse_distribution",
    "parse_source",
    "Source",
    "LawSite",
    "ParseError",
    "nnf",
    "check",
    "classify",
    "is_co_safe",
    "event_distributions",
    "horizon",
    "FragmentError",
    "FragmentReport",
    "holds",
    "holds_lasso",
    "Verdict",
    "Formula",
    "Const",
    "Prop",
    "Not",
    "And",
    "Or",
    "Until",
    "Release",
    "Next",
    "Dist",
    "Interval",
    "DistRef",
    "DistLiteral",
    "DistSpec",
    "TRUE",
    "FALSE",
    "conj",
    "disj",
    "neg",
    "implies",
    "until",
    "release",
    "weak",
    "eventually",
    "always",
    "nxt",
    "dist",
    "atoms",
    "subformulas",
]


def __getattr__(name: str) -> Any:
    """A public name of a module imported on first use (PEP 562)."""
    where = _LAZY.get(name)
    if where is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(where), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))

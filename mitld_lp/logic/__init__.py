"""MITLD formulas: the AST, the parser, the supported fragment and reference evaluators.

The reference evaluators (:mod:`.semantics`: ``holds``, ``holds_lasso``, ``Verdict``) are
imported on first use: a solve reads formulas but never evaluates one on a word."""

from typing import TYPE_CHECKING

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
from mitld_lp.util.lazy import lazy_names

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

__getattr__, __dir__ = lazy_names(globals(), _LAZY)

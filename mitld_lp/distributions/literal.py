"""The written forms of a law and their one way to a built law: the formula literal
``D[family(args)]`` (:class:`DistLiteral`, a node of the formula AST) and a model file's
inline table ``{ family = value }`` (:func:`from_table`), both through
:data:`~.families.FAMILIES`.

A literal builds its law once, the first time :attr:`DistLiteral.law` is read (the
parser reads it to validate the values at the literal's position), and keeps it: every
later stage that needs the law of that node (the fragment check, the binding of events to
laws) gets the same object instead of building it again.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from mitld_lp.distributions.families import FAMILIES, build
from mitld_lp.distributions.law import DistributionError, FirstOccurrence
from mitld_lp.distributions.printing import DistArg, literal_text

__all__ = ["DistLiteral", "from_spec", "from_table"]


@dataclass(frozen=True, slots=True)
class DistLiteral:
    """An inline distribution literal such as ``geometric(0.3)`` or
    ``scipy(nbinom, 3, 0.5)``: the family name and the arguments as written.

    Equality and hashing are by ``(family, args)``.  Making one checks nothing; whether
    the arguments define a law is known when :attr:`law` is first read.
    """

    family: str
    args: tuple[DistArg, ...]
    _law: FirstOccurrence | None = field(default=None, init=False, repr=False, compare=False)

    def __str__(self) -> str:
        return literal_text(self.family, self.args)

    def __reduce__(self) -> tuple[type[DistLiteral], tuple[str, tuple[DistArg, ...]]]:
        # The built law is a cache (it may hold a scipy object): pickle the text only.
        return (DistLiteral, (self.family, self.args))

    @property
    def law(self) -> FirstOccurrence:
        """The law this literal writes, built from :data:`FAMILIES` on first read and
        kept (its label is ``str(self)``).  Raises :class:`DistributionError` for an
        unknown family, a wrong number of arguments or invalid values (each read of an
        invalid literal raises again)."""
        law = self._law
        if law is None:
            law = build(self.family, self.args, str(self))
            object.__setattr__(self, "_law", law)
        return law


def from_spec(spec: object) -> FirstOccurrence:
    """The law of an inline formula literal such as ``geometric(0.3)``,
    ``pmf(0.1, 0.3, 0.6)`` or ``scipy(nbinom, 3, 0.5)``: its :attr:`DistLiteral.law`
    (the same object on every call for one literal).  A name (``D[mu]``) is an error: it
    is bound by the model."""
    if not isinstance(spec, DistLiteral):
        raise DistributionError(
            str(spec), "is a name, not a distribution literal; bind it in the model file"
        )
    return spec.law


def from_table(value: object, path: str, base: Path | None = None) -> FirstOccurrence:
    """The distribution of a model file's inline table with exactly one key, e.g.
    ``{ geometric = 0.8 }``, ``{ pmf = [0.1, 0.3, 0.6] }``, ``{ poisson = 2.5 }``,
    ``{ uniform = [1, 6] }``, ``{ exponential = 0.5 }``, ``{ weibull = [1.5, 3.0] }``,
    ``{ gamma = [2.0, 1.5] }``, ``{ scipy = ["nbinom", 3, 0.5] }``; a band: an interval
    parameter ``{ geometric = [0.2, 0.4] }`` (:func:`~.band.interval`) or a fit
    ``{ fit = "geometric", data = "arrivals.csv", confidence = 0.95 }``
    (:func:`~.fit.fit_table`, ``data`` relative to ``base``).

    Errors name the key path: ``distributions.mu2.pmf: masses sum to 1.2 > 1``.
    """
    example = "{ geometric = 0.8 }"
    if not isinstance(value, Mapping):
        raise DistributionError(
            path,
            f"must be an inline table with one distribution key such as {example}, got {value!r}",
        )
    if "fit" in value:  # the fit's module (and SciPy's) only for a fitted law
        from mitld_lp.distributions.fit import fit_table

        return fit_table(value, path, base)
    if len(value) != 1:
        keys = ", ".join(str(k) for k in value) or "none"
        raise DistributionError(
            path, f"must have exactly one distribution key ({', '.join(FAMILIES)}), got {keys}"
        )
    ((family, arg),) = value.items()
    where = f"{path}.{family}"
    if family not in FAMILIES:
        raise DistributionError(
            path, f"unknown distribution {family!r}; expected one of {', '.join(FAMILIES)}"
        )
    if FAMILIES[family].takes_list:
        if not isinstance(arg, list | tuple):
            raise DistributionError(where, f"must be a list, got {arg!r}")
        args = list(arg)
    else:
        if isinstance(arg, list | tuple) and len(arg) == 2:
            from mitld_lp.distributions.band import interval  # a band: its module then

            return interval(str(family), arg[0], arg[1], where)
        if isinstance(arg, list | tuple | Mapping | str):
            raise DistributionError(where, f"must be a number, got {arg!r} (an interval "
                                    "is written [lo, hi])")
        args = [arg]
    try:
        return build(str(family), args, where)
    except DistributionError as exc:
        raise DistributionError(where, exc.reason) from exc

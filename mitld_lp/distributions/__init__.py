"""First-occurrence distributions of external events over the steps 1, 2, ...

An external event ``a`` happens at most once; its first-occurrence step ``K`` takes values
in ``{1, 2, ...}`` with pmf ``mu(k) = P(K = k)``; the mass the law leaves undefined is
the probability ``never`` that the event never happens.  The automaton needs its hazard
``h(k) = mu(k) / S(k-1)`` with ``S(k) = P(K > k)``, and either the step from which the
hazard is constant or a truncation point.

The package, cut by concern (nothing here imports the formula layer; it imports this):

* :mod:`.law`: the type :class:`FirstOccurrence` and its numerics (pmf, cdf, survival,
  hazard, constant-hazard step, truncation point, sampling), :class:`DistributionError`
  and the numeric limits;
* :mod:`.closed`: the geometric, finite tables and the long uniform, without scipy;
* :mod:`.scipy_laws`: the adapters for ``scipy.stats`` laws (imported lazily);
* :mod:`.families`: each family's constructor and parameter checks, and the registry
  :data:`FAMILIES`;
* :mod:`.printing`: how a literal is written (labels and the formula printer share it);
* :mod:`.literal`: the written forms -- the formula node :class:`DistLiteral`, which
  builds its law once, and a model file's inline table (:func:`from_table`).

Each name is imported from its module on first use (PEP 562): a solve whose task names
no law (a PRISM property) imports none of them.
"""

from typing import TYPE_CHECKING

from mitld_lp.util.lazy import lazy_names

if TYPE_CHECKING:
    from mitld_lp.distributions.families import (
        FAMILIES,
        Family,
        discretised,
        exponential,
        gamma,
        geometric,
        pmf,
        poisson,
        scipy_discrete,
        uniform,
        weibull,
    )
    from mitld_lp.distributions.law import (
        HAZARD_ATOL,
        HAZARD_RTOL,
        MASS_TOLERANCE,
        MAX_HAZARD_SCAN,
        MAX_STEP,
        MAX_TABLE_STEPS,
        NEGLIGIBLE_TAIL,
        DistributionError,
        FirstOccurrence,
    )
    from mitld_lp.distributions.literal import DistLiteral, from_spec, from_table
    from mitld_lp.distributions.printing import DistArg


_WHERE = {
    **dict.fromkeys(("FAMILIES", "Family", "discretised", "exponential", "gamma", "geometric",
                     "pmf", "poisson", "scipy_discrete", "uniform", "weibull"),
                    "mitld_lp.distributions.families"),
    **dict.fromkeys(("HAZARD_ATOL", "HAZARD_RTOL", "MASS_TOLERANCE", "MAX_HAZARD_SCAN",
                     "MAX_STEP", "MAX_TABLE_STEPS", "NEGLIGIBLE_TAIL", "DistributionError",
                     "FirstOccurrence"), "mitld_lp.distributions.law"),
    **dict.fromkeys(("DistLiteral", "from_spec", "from_table"),
                    "mitld_lp.distributions.literal"),
    "DistArg": "mitld_lp.distributions.printing",
}

__all__ = [
    "DistributionError",
    "FirstOccurrence",
    "geometric",
    "pmf",
    "poisson",
    "uniform",
    "scipy_discrete",
    "discretised",
    "exponential",
    "weibull",
    "gamma",
    "from_spec",
    "from_table",
    "FAMILIES",
    "Family",
    "DistLiteral",
    "DistArg",
    "MASS_TOLERANCE",
    "HAZARD_RTOL",
    "HAZARD_ATOL",
    "NEGLIGIBLE_TAIL",
    "MAX_HAZARD_SCAN",
    "MAX_TABLE_STEPS",
    "MAX_STEP",
]

__getattr__, __dir__ = lazy_names(globals(), _WHERE)

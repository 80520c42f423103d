"""Laws fitted to observed first-occurrence times, right-censored ones included, with a
confidence band (:func:`fit_law`; a model file's ``{ fit = ..., data = ... }``).

An observation is a step ``t``: either the event came at step ``t >= 1``, or it had not
come by step ``c >= 0`` when watching stopped (*right-censored*: ``K > c``).  Censored
observations are neither dropped nor read as events; every likelihood below is

    L(theta) = prod_{events} mu_theta(t_i) * prod_{censored} S_theta(c_j).

* ``geometric``: closed form.  With ``d`` events and the *exposure*
  ``E = sum t_i + sum c_j`` (the steps watched; each is a Bernoulli trial of hazard
  ``p``) the likelihood is ``p^d (1-p)^(E-d)``, so ``p_hat = d / E``; the band is the
  Clopper-Pearson interval for ``d`` successes in ``E`` trials,
  ``[Beta(a/2; d, E-d+1), Beta(1-a/2; d+1, E-d)]`` with ``a = 1 - confidence``, a
  constant hazard band (memoryless, exact).
* ``empirical``: the Kaplan-Meier estimate ``S(k) = prod_{j<=k} (1 - d_j / n_j)`` (``n_j``
  at risk at step ``j``: events at ``t >= j`` and censorings at ``c >= j``) as the point
  law, and a simultaneous band valid whatever the censoring: the complete sample's
  empirical survival lies between ``S_pess`` (each censored time read as an event right
  after it) and ``S_opt`` (read as never), and by the Dvoretzky-Kiefer-Wolfowitz
  inequality with Massart's constant it is within ``eps = sqrt(ln(2/a) / (2n))`` of the
  truth at every step at once with probability ``>= 1 - a``; so
  ``S(k) in [S_pess(k) - eps, S_opt(k) + eps]`` for all ``k``.
* ``poisson`` and ``nbinom`` (``K = 1 + X``): the censored likelihood above maximised
  numerically (``scipy.optimize``).
* ``exponential``, ``weibull``, ``gamma`` and any continuous ``scipy.stats`` family
  (``K = ceil(X)``, ``loc = 0``): ``scipy.stats`` ``fit`` with ``CensoredData``, an event
  at step ``t`` being ``X in (t-1, t]`` and a censoring at ``c`` being ``X > c``.

For the numeric families the band is the envelope of the laws in the likelihood-ratio
region ``{theta : 2 (l(theta_hat) - l(theta)) <= chi2_d(confidence)}``, ``d`` the number
of parameters: for one parameter its two ends (exact: these families' survival is
monotone in their parameter); for more, points of its boundary found along
:data:`DIRECTIONS` rays shaped by the observed information (an approximation of the
region's image, said in :attr:`Fit.method`).

Data files are CSV: a header naming the column ``time`` and optionally ``censored``
(``0``/``1``, ``true``/``false``, ``yes``/``no``), one observation a line; blank lines
and lines starting with ``#`` are skipped.
"""

from __future__ import annotations

import csv
import logging
import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
import numpy.typing as npt

from mitld_lp.distributions import scipy_laws
from mitld_lp.distributions.band import ConstantBand, TableBand, band_of_laws
from mitld_lp.distributions.families import (
    discretised,
    exponential,
    gamma,
    geometric,
    pmf,
    poisson,
    scipy_discrete,
    weibull,
)
from mitld_lp.distributions.law import DistributionError, FirstOccurrence
from mitld_lp.distributions.printing import literal_text
from mitld_lp.files import rules as file_rules

__all__ = [
    "MIN_OBSERVATIONS", "DIRECTIONS", "FIT_FAMILIES", "Observations", "Parameter", "Fit",
    "observations", "read_observations", "fit_law", "kaplan_meier", "fit_table",
]

#: A fit needs at least this many observations (and at least one event).
MIN_OBSERVATIONS = 10
#: Rays along which the boundary of a likelihood region of two or more parameters is found.
DIRECTIONS = 32
#: The families fitted by name (any other continuous ``scipy.stats`` name also works).
FIT_FAMILIES = ("geometric", "empirical", "poisson", "nbinom", "exponential", "weibull",
                "gamma")

IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True, slots=True, eq=False)
class Observations:
    """Observed first-occurrence steps: ``times[i]`` is an event step (``>= 1``) or, where
    ``censored[i]``, the last step watched without the event (``>= 0``)."""

    times: IntArray
    censored: BoolArray
    source: str

    @property
    def n(self) -> int:
        return int(self.times.size)

    @property
    def events(self) -> int:
        return int(np.count_nonzero(~self.censored))

    @property
    def exposure(self) -> int:
        """The steps watched in all: ``sum t_i + sum c_j``."""
        return int(self.times.sum())


def observations(
    times: Sequence[Any] | npt.NDArray[Any],
    censored: Sequence[Any] | npt.NDArray[Any] | None = None,
    *,
    source: str = "data",
) -> Observations:
    """``times`` and ``censored`` (default: none censored) checked: integers, event
    steps ``>= 1``, censoring steps ``>= 0``, at least :data:`MIN_OBSERVATIONS`
    observations and one event.  Raises :class:`DistributionError` naming ``source``
    (and the observation)."""
    values = list(np.asarray(times, dtype=object).ravel())
    flags = [False] * len(values) if censored is None else list(
        np.asarray(censored, dtype=object).ravel())
    if len(flags) != len(values):
        raise DistributionError(source, f"{len(values)} times but {len(flags)} censoring flags")
    out = np.empty(len(values), dtype=np.int64)
    cens = np.empty(len(values), dtype=bool)
    for i, (t, c) in enumerate(zip(values, flags, strict=True)):
        where = f"observation {i + 1}"
        cens[i] = _flag(c, f"{source}: {where}")
        out[i] = _time(t, bool(cens[i]), f"{source}: {where}")
    return _checked(Observations(out, cens, source))


def _flag(value: Any, where: str) -> bool:
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer) and int(value) in (0, 1):
        return bool(value)
    text = str(value).strip().lower()
    if text in ("0", "false", "no"):
        return False
    if text in ("1", "true", "yes"):
        return True
    raise DistributionError(where, f"censored must be 0/1, true/false or yes/no, got {value!r}")


def _time(value: Any, censored: bool, where: str) -> int:
    if isinstance(value, bool | np.bool_):
        raise DistributionError(where, f"time must be an integer, got {value!r}")
    if isinstance(value, str):
        text = value.strip()
        try:
            value = int(text)
        except ValueError:
            try:
                value = float(text)
            except ValueError:
                raise DistributionError(where, f"time must be an integer, got {text!r}") from None
    if isinstance(value, float | np.floating):
        if not (math.isfinite(value) and value == math.floor(value)):
            raise DistributionError(where, f"time must be an integer, got {value!r}")
        value = int(value)
    if not isinstance(value, int | np.integer):
        raise DistributionError(where, f"time must be an integer, got {value!r}")
    t = int(value)
    if t < 0:
        raise DistributionError(where, f"time must be >= 0, got {t}")
    if t == 0 and not censored:
        raise DistributionError(
            where, "an event time must be >= 1 (no event happens at step 0; a run "
            "watched for 0 steps is censored at 0)")
    if t >= 2**62:
        raise DistributionError(where, f"time is beyond the last step 2**62, got {t}")
    return t


def _checked(obs: Observations) -> Observations:
    if obs.n < MIN_OBSERVATIONS:
        raise DistributionError(
            obs.source, f"{obs.n} observations; a fit needs at least {MIN_OBSERVATIONS}")
    if obs.events == 0:
        raise DistributionError(
            obs.source, f"all {obs.n} observations are censored: no event was seen, so "
            "nothing bounds how late it comes")
    return obs


def read_observations(path: str | Path, source: str | None = None, *,
                      max_memory: int | None = None) -> Observations:
    """The observations of a CSV file (module docstring).  Errors name ``source``
    (default: the path) and the line: ``arrivals.csv:4: time must be >= 0, got -2``.
    Only a regular file is read, up to ``file_rules.read_limit(max_memory)``."""
    name = str(path) if source is None else source
    try:
        lines = file_rules.read_text(path, file_rules.read_limit(max_memory)).splitlines()
    except OSError as exc:
        raise DistributionError(name, f"cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise DistributionError(name, f"not UTF-8 text: {exc}") from None
    rows = [(i, row) for i, row in enumerate(csv.reader(lines), start=1)
            if row and any(x.strip() for x in row) and not row[0].lstrip().startswith("#")]
    if not rows:
        raise DistributionError(name, "no header: the first line must name the column "
                                "'time' (and optionally 'censored')")
    line, header = rows[0]
    cols = [h.strip().lower() for h in header]
    if "time" not in cols or any(c not in ("time", "censored") for c in cols) or len(
            set(cols)) != len(cols):
        raise DistributionError(
            f"{name}:{line}", f"the header must name the column 'time' and optionally "
            f"'censored', got {','.join(header)!r}")
    t_at, c_at = cols.index("time"), cols.index("censored") if "censored" in cols else None
    times, flags = [], []
    for line, row in rows[1:]:
        where = f"{name}:{line}"
        if len(row) != len(cols):
            raise DistributionError(where, f"expected {len(cols)} values, got {len(row)}")
        flag = False if c_at is None else _flag(row[c_at], where)
        times.append(_time(row[t_at], flag, where))
        flags.append(flag)
    return _checked(Observations(np.array(times, dtype=np.int64).reshape(-1),
                                 np.array(flags, dtype=bool).reshape(-1), name))


# --------------------------------------------------------------------------- results


@dataclass(frozen=True, slots=True)
class Parameter:
    """One fitted parameter: the estimate and its interval in the band."""

    name: str
    estimate: float
    lo: float
    hi: float


@dataclass(frozen=True, slots=True, eq=False)
class Fit:
    """A fitted law: ``point`` (the maximum-likelihood or Kaplan-Meier law), ``band``
    (the law the model uses: every law the data still allow at ``confidence``, a
    :class:`~.band.Band`), the parameters with their intervals (none for
    ``empirical``), the data, and ``method``: how both were computed, in one line."""

    family: str
    confidence: float
    data: Observations
    point: FirstOccurrence
    band: FirstOccurrence
    parameters: tuple[Parameter, ...]
    log_likelihood: float
    method: str


# --------------------------------------------------------------------------- fitting


def _check_confidence(confidence: Any, where: str) -> float:
    if isinstance(confidence, bool) or not isinstance(confidence, int | float):
        raise DistributionError(where, f"confidence must be a number, got {confidence!r}")
    c = float(confidence)
    if not 0 < c < 1:
        raise DistributionError(where, f"confidence must be in (0, 1), got {confidence!r}")
    return c


def fit_law(
    times: Sequence[Any] | npt.NDArray[Any] | Observations,
    censored: Sequence[Any] | npt.NDArray[Any] | None = None,
    *,
    family: str = "geometric",
    confidence: float = 0.95,
    label: str | None = None,
) -> Fit:
    """Fit ``family`` to the observed ``times`` (``censored[i]``: ``times[i]`` is the last
    step watched without the event) and return the point law and its ``confidence``
    band (module docstring).  ``label`` names the band (default
    ``fit(family, n=N, confidence)``).  Raises :class:`DistributionError`."""
    obs = times if isinstance(times, Observations) else observations(times, censored)
    conf = _check_confidence(confidence, obs.source)
    if not isinstance(family, str) or not family:
        raise DistributionError(obs.source, f"fit: family must be a name, got {family!r}")
    name = label or f"fit({family}, n={obs.n}, {conf:g})"
    if family == "geometric":
        return _fit_geometric(obs, conf, name)
    if family == "empirical":
        return _fit_empirical(obs, conf, name)
    return _fit_numeric(obs, family, conf, name)


def _fit_geometric(obs: Observations, conf: float, label: str) -> Fit:
    from scipy import stats

    d, e = obs.events, obs.exposure
    a = 1.0 - conf
    p_hat = d / e
    lo = 0.0 if d == 0 else float(stats.beta.ppf(a / 2, d, e - d + 1))
    hi = 1.0 if d == e else float(stats.beta.ppf(1 - a / 2, d + 1, e - d))
    lo, hi = min(lo, p_hat), max(hi, p_hat)
    point = geometric(p_hat)
    band = ConstantBand(label, point, lo, hi)
    ll = d * math.log(p_hat) + ((e - d) * math.log1p(-p_hat) if e > d else 0.0)
    return Fit("geometric", conf, obs, point, band, (Parameter("p", p_hat, lo, hi),), ll,
               f"p = events / exposure = {d}/{e}; Clopper-Pearson {conf:g} interval")


def kaplan_meier(obs: Observations) -> npt.NDArray[np.float64]:
    """``S[k]`` for ``k = 0..max time``: ``S(k) = prod_{j<=k} (1 - d_j / n_j)`` with
    ``d_j`` the events at step ``j`` and ``n_j`` the observations at risk there (events
    at ``t >= j``, censorings at ``c >= j``); constant where nobody is at risk."""
    m = int(obs.times.max())
    ev = np.bincount(obs.times[~obs.censored], minlength=m + 1).astype(np.float64)
    # at risk at j: event times >= j plus censoring times >= j
    counts = np.bincount(obs.times, minlength=m + 2).astype(np.float64)
    at_risk = np.cumsum(counts[::-1])[::-1][: m + 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(at_risk > 0, 1.0 - ev / at_risk, 1.0)
    factor[0] = 1.0
    return np.cumprod(factor).astype(np.float64)


def _fit_empirical(obs: Observations, conf: float, label: str) -> Fit:
    s = kaplan_meier(obs)
    masses = -np.diff(s)
    point = pmf(np.clip(masses, 0.0, None))
    n, m = obs.n, int(obs.times.max())
    eps = math.sqrt(math.log(2.0 / (1.0 - conf)) / (2.0 * n))
    k = np.arange(m + 2)
    ev_t, c_t = obs.times[~obs.censored], obs.times[obs.censored]
    events_by = np.searchsorted(np.sort(ev_t), k, side="right")  # events with t <= k
    s_opt = 1.0 - events_by / n
    s_pess = ((ev_t.size - events_by) + (c_t.size - np.searchsorted(np.sort(c_t), k,
                                                                     side="left"))) / n
    band = TableBand(label, point, np.clip(s_pess - eps, 0.0, 1.0),
                     np.clip(s_opt + eps, 0.0, 1.0))
    ev_s = s[np.minimum(ev_t, m)]
    ev_prev = s[np.minimum(ev_t - 1, m)]
    with np.errstate(divide="ignore"):
        ll = float(np.sum(np.log(np.maximum(ev_prev - ev_s, 0.0))) + np.sum(np.log(s[c_t])))
    return Fit("empirical", conf, obs, point, band, (), ll,
               f"Kaplan-Meier; simultaneous band S_pess - {eps:.4g} .. S_opt + {eps:.4g} "
               f"(DKW, {conf:g})")


# ------------------------------------------------------------------ numeric families


@dataclass(frozen=True, slots=True)
class _Family:
    """How a numeric family is parametrised: names, each parameter's transform to the
    real line (``log`` for positive, ``logit`` for (0, 1)) and the law of a vector."""

    params: tuple[str, ...]
    transforms: tuple[str, ...]
    law: Callable[[np.ndarray], FirstOccurrence]
    start: Callable[[Observations], np.ndarray] | None  # None: scipy's fit gives it


def _mean_event(obs: Observations) -> float:
    return float(np.mean(obs.times[~obs.censored]))


def _family(name: str, where: str) -> tuple[_Family, Any]:
    """The parametrisation of ``name`` and, for continuous families, scipy's generator."""
    if name == "poisson":
        return _Family(("lam",), ("log",), lambda th: poisson(float(th[0])),
                       lambda o: np.array([max(_mean_event(o) - 1.0, 0.1)])), None
    if name == "nbinom":
        return _Family(("n", "p"), ("log", "logit"),
                       lambda th: scipy_discrete("nbinom", float(th[0]), float(th[1])),
                       lambda o: np.array([1.0, 1.0 / max(_mean_event(o), 1.5)])), None
    scipy_name = {"exponential": "expon", "weibull": "weibull_min"}.get(name, name)
    gen = scipy_laws.generator(where, scipy_name)
    if not isinstance(gen, scipy_laws.stats().rv_continuous):
        raise DistributionError(
            where, f"fit: cannot fit {name!r}; expected one of {', '.join(FIT_FAMILIES)} or "
            "a continuous scipy.stats family")
    shapes = tuple(s.strip() for s in (gen.shapes or "").split(",") if s.strip())
    if name == "exponential":
        return _Family(("rate",), ("log",), lambda th: exponential(float(th[0])), None), gen
    if name == "weibull":
        return _Family(("shape", "scale"), ("log", "log"),
                       lambda th: weibull(float(th[0]), float(th[1])), None), gen
    if name == "gamma":
        return _Family(("shape", "scale"), ("log", "log"),
                       lambda th: gamma(float(th[0]), float(th[1])), None), gen
    return _Family((*shapes, "scale"), ("raw",) * len(shapes) + ("log",),
                   lambda th: discretised(scipy_name, *map(float, th[:-1]), 0.0,
                                          float(th[-1])), None), gen


def _to_real(theta: np.ndarray, transforms: Sequence[str]) -> np.ndarray:
    out = np.array(theta, dtype=np.float64)
    for i, t in enumerate(transforms):
        if t == "log":
            out[i] = math.log(theta[i])
        elif t == "logit":
            out[i] = math.log(theta[i] / (1.0 - theta[i]))
    return out


def _from_real(x: np.ndarray, transforms: Sequence[str]) -> np.ndarray:
    out = np.array(x, dtype=np.float64)
    with np.errstate(over="ignore"):
        for i, t in enumerate(transforms):
            if t == "log":
                out[i] = math.exp(min(x[i], 700.0))
            elif t == "logit":
                out[i] = 1.0 / (1.0 + math.exp(-min(max(x[i], -700.0), 700.0)))
    return out


def _log_likelihood(obs: Observations) -> Callable[[FirstOccurrence], float]:
    """``law -> sum log mu(t_i) + sum log S(c_j)`` over the distinct times."""
    ev, ev_n = np.unique(obs.times[~obs.censored], return_counts=True)
    ce, ce_n = np.unique(obs.times[obs.censored], return_counts=True)

    def ll(law: FirstOccurrence) -> float:
        with np.errstate(divide="ignore"):
            total = float(np.dot(ev_n, np.log(np.asarray(law.pmf(ev), dtype=np.float64))))
            if ce.size:
                total += float(np.dot(ce_n, np.log(np.asarray(law.survival(ce),
                                                               dtype=np.float64))))
        return total if math.isfinite(total) else -math.inf

    return ll


def _scipy_start(obs: Observations, gen: Any, where: str) -> np.ndarray:
    """scipy's censored maximum-likelihood fit with ``loc = 0``: events as the intervals
    ``(t-1, t]``, censorings as ``X > c``; the shapes then the scale."""
    from scipy import stats

    ev = obs.times[~obs.censored].astype(np.float64)
    data = stats.CensoredData(interval=np.column_stack([ev - 1.0, ev]),
                              right=obs.times[obs.censored].astype(np.float64))
    try:
        fitted = gen.fit(data, floc=0)
    except Exception as exc:  # scipy's optimisers raise many kinds  # noqa: BLE001
        raise DistributionError(where, f"fit: scipy could not fit {gen.name}: {exc}") from None
    theta = np.array([*fitted[:-2], fitted[-1]], dtype=np.float64)
    if not np.all(np.isfinite(theta)):
        raise DistributionError(where, f"fit: scipy's fit of {gen.name} is not finite")
    return theta


def _fit_numeric(obs: Observations, name: str, conf: float, label: str) -> Fit:
    with warnings.catch_warnings(record=True) as seen:  # scipy's: logged for -v, not shown
        warnings.simplefilter("always")
        try:
            return _fit_scipy(obs, name, conf, label)
        finally:
            for w in {(w.category.__name__, str(w.message)) for w in seen}:
                logging.getLogger(__name__).debug("fit %s: %s: %s", obs.source, *w)


def _fit_scipy(obs: Observations, name: str, conf: float, label: str) -> Fit:
    from scipy import optimize, stats

    where = obs.source
    fam, gen = _family(name, where)
    if fam.params and np.unique(obs.times[~obs.censored]).size < len(fam.params):
        raise DistributionError(
            where, f"fit: {name} has {len(fam.params)} parameters but the events fall on "
            f"{np.unique(obs.times[~obs.censored]).size} distinct step(s)")
    ll_of = _log_likelihood(obs)

    def nll(x: np.ndarray) -> float:
        try:
            return -ll_of(fam.law(_from_real(x, fam.transforms)))
        except (DistributionError, ValueError, OverflowError, ZeroDivisionError):
            return math.inf

    theta0 = fam.start(obs) if fam.start is not None else _scipy_start(obs, gen, where)
    x0 = _to_real(theta0, fam.transforms)
    best = optimize.minimize(nll, x0, method="Nelder-Mead",
                             options={"xatol": 1e-10, "fatol": 1e-12, "maxiter": 4000})
    x_hat = best.x if best.fun <= nll(x0) else x0
    ll_hat = -nll(x_hat)
    if not math.isfinite(ll_hat):
        raise DistributionError(where, f"fit: the {name} likelihood of these data is 0 "
                                "everywhere it was evaluated")
    theta_hat = _from_real(x_hat, fam.transforms)
    point = fam.law(theta_hat)
    q = float(stats.chi2.ppf(conf, len(fam.params)))
    boundary = _region_boundary(nll, x_hat, -ll_hat, q)
    thetas = [_from_real(x, fam.transforms) for x in boundary]
    laws = [fam.law(th) for th in thetas]
    band = band_of_laws(label, point, laws)
    every = np.vstack([theta_hat, *thetas])
    params = tuple(Parameter(p, float(theta_hat[i]), float(every[:, i].min()),
                             float(every[:, i].max())) for i, p in enumerate(fam.params))
    how = "two ends" if len(fam.params) == 1 else f"{len(boundary)} boundary points"
    source = "scipy fit (CensoredData), polished" if gen is not None else "Nelder-Mead"
    return Fit(name, conf, obs, point, band, params, ll_hat,
               f"censored maximum likelihood ({source}); likelihood-ratio {conf:g} region, "
               f"{how}")


def _directions(d: int) -> np.ndarray:
    if d == 1:
        return np.array([[1.0], [-1.0]])
    if d == 2:
        a = np.linspace(0.0, 2 * math.pi, DIRECTIONS, endpoint=False)
        return np.column_stack([np.cos(a), np.sin(a)])
    rng = np.random.default_rng(0)
    u = rng.standard_normal((DIRECTIONS * d, d))
    u = np.vstack([np.eye(d), -np.eye(d), u])
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _hessian(f: Callable[[np.ndarray], float], x: np.ndarray, h: float = 1e-3) -> np.ndarray:
    d = x.size
    out = np.empty((d, d))
    f0 = f(x)
    for i in range(d):
        for j in range(i, d):
            ei, ej = np.eye(d)[i] * h, np.eye(d)[j] * h
            if i == j:
                v = (f(x + ei) - 2 * f0 + f(x - ei)) / h**2
            else:
                v = (f(x + ei + ej) - f(x + ei - ej) - f(x - ei + ej) + f(x - ei - ej)) / (
                    4 * h**2)
            out[i, j] = out[j, i] = v
    return out


def _region_boundary(
    nll: Callable[[np.ndarray], float], x_hat: np.ndarray, nll_hat: float, q: float
) -> list[np.ndarray]:
    """Points ``x`` with ``2 (nll(x) - nll_hat) = q`` along rays from ``x_hat`` (in the
    transformed coordinates), shaped by the inverse observed information."""
    from scipy import optimize

    d = x_hat.size
    hess = _hessian(nll, x_hat)
    try:
        shape = np.linalg.cholesky(np.linalg.inv(hess)) if np.all(np.isfinite(hess)) else None
    except np.linalg.LinAlgError:
        shape = None
    if shape is None or not np.all(np.isfinite(shape)):
        shape = np.eye(d) * 0.1

    def excess(r: float, u: np.ndarray) -> float:
        v = nll(x_hat + r * (shape @ u))
        return (2.0 * (v - nll_hat) - q) if math.isfinite(v) else math.inf

    def ray(u: np.ndarray) -> float:
        """The ``r`` where the ray leaves the region (or the parameter space)."""
        lo, hi = 0.0, math.sqrt(q)
        while (f_hi := excess(hi, u)) < 0:
            lo, hi = hi, 2.0 * hi
            if hi > 1e6:
                return lo
        for _ in range(200):
            if math.isfinite(f_hi):
                return float(cast(float, optimize.brentq(excess, lo, hi, args=(u,), xtol=1e-12)))
            mid = (lo + hi) / 2.0
            f_mid = excess(mid, u)
            if f_mid < 0:
                lo = mid
            else:
                hi, f_hi = mid, f_mid
        return lo

    return [x_hat + ray(u) * (shape @ u) for u in _directions(d)]


# --------------------------------------------------------------------------- model files


def fit_table(value: Mapping[str, Any], path: str, base: Path | None) -> FirstOccurrence:
    """The law of a model file's ``{ fit = "geometric", data = "arrivals.csv",
    confidence = 0.95 }`` (``data`` relative to ``base``, the model file's folder; the
    working directory when None): the fit's band.  Errors name the key path."""
    allowed = {"fit", "data", "confidence"}
    extra = sorted(set(value) - allowed)
    if extra:
        raise DistributionError(f"{path}.{extra[0]}", "unknown key; a fit takes fit, data "
                                "and confidence")
    family = value["fit"]
    if not isinstance(family, str) or not family:
        raise DistributionError(f"{path}.fit", f"must be a family name such as 'geometric', "
                                f"got {family!r}")
    if "data" not in value:
        raise DistributionError(path, "a fit needs data = \"FILE.csv\" (time,censored)")
    data = value["data"]
    if not isinstance(data, str) or not data:
        raise DistributionError(f"{path}.data", f"must be a file name, got {data!r}")
    conf = _check_confidence(value.get("confidence", 0.95), f"{path}.confidence")
    file = Path(data) if base is None else base / data
    obs = read_observations(file, data)
    label = literal_text("fit", (family, data, conf))
    try:
        return fit_law(obs, family=family, confidence=conf, label=label).band
    except DistributionError as exc:
        raise DistributionError(f"{path}.fit", str(exc)) from None

"""The start made lean (branch start-lean): the laws in closed form against SciPy and
exact decimals, the spec parsed once, and the imports a PRISM solve no longer pays."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from decimal import Decimal, localcontext
from pathlib import Path

import numpy as np
import pytest
import scipy.stats as st

from mitld_lp import distributions as D
from mitld_lp.distributions.poisson_law import PoissonX
from mitld_lp.distributions.weibull_law import WeibullX

ROOT = Path(__file__).resolve().parents[1]
LAMBDAS = [1e-3, 0.05, 0.3, 0.69, 1.0, 2.0, 3.7, 10.0, 25.5]


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b) / b))


@pytest.mark.parametrize("lam", LAMBDAS)
def test_poisson_pmf_cdf_sf_match_scipy(lam: float) -> None:
    """Where SciPy's values are at least 1e-30 (below, both sides' exponents carry
    ``|log pmf|`` ulps of rounding each), to a relative 1e-13; below 0 as SciPy."""
    x = np.arange(-3, int(lam + 40 * math.sqrt(lam) + 60))
    ours, ref = PoissonX(lam), st.poisson(lam)
    for name in ("pmf", "cdf", "sf"):
        a, b = getattr(ours, name)(x), getattr(ref, name)(x)
        keep = b >= 1e-30
        assert keep.sum() > 5
        assert _rel(a[keep], b[keep]) <= 1e-13, name
        assert np.array_equal(a[x < 0], b[x < 0]), name  # 0, 0 and 1 below the support
    lp, lr = ours.logpmf(x), ref.logpmf(x)
    keep = np.isfinite(lr) & (lr > -69)
    assert np.max(np.abs(lp[keep] - lr[keep])) <= 1e-13 * max(1.0, float(np.abs(lr[keep]).max()))
    assert np.all(np.isneginf(lp[x < 0]))


@pytest.mark.parametrize("lam", [0.3, 2.0, 100.0, 1000.0])
def test_poisson_against_exact_decimals(lam: float) -> None:
    """An independent route: the pmf by the recurrence in 60-digit decimals, the head
    and the tail as exact sums of it.  Ours holds a relative 1e-12 up to lam = 1000 on
    values of at least 1e-100 (SciPy's own pmf there is off by more: about 2e-12)."""
    hi = int(lam + 40 * math.sqrt(lam) + 60)
    with localcontext() as ctx:
        ctx.prec = 60
        big_l = Decimal(lam)
        p = [(-big_l).exp()]
        for j in range(1, hi + 400):
            p.append(p[-1] * big_l / j)
        xs = np.unique(np.linspace(0, hi - 1, 30).astype(np.int64))
        ours = PoissonX(lam)
        for name in ("pmf", "cdf", "sf"):
            got = getattr(ours, name)(xs)
            for x, g in zip(xs.tolist(), got.tolist(), strict=True):
                exact = {"pmf": p[x], "cdf": sum(p[: x + 1]), "sf": sum(p[x + 1:])}[name]
                if exact < Decimal("1e-100"):
                    continue
                assert abs(Decimal(g) - exact) / exact <= Decimal("1e-12"), (name, x)


@pytest.mark.parametrize("lam", [2.0, 25.5])
def test_poisson_hazard_increases_towards_one_past_the_tails_underflow(lam: float) -> None:
    """A Poisson hazard never decreases (its pmf is log-concave) and the law says so
    (``hazard_range_from``): it must hold also where the tail is subnormal or 0."""
    law = D.poisson(lam)
    h = law.hazard(np.arange(1, int(lam) + 800))
    assert np.all(np.diff(h) >= 0) and np.all(h <= 1.0) and h[-1] > 0.95
    assert law.hazard_range_from(40 + int(lam))[0] <= h[-1]


@pytest.mark.parametrize(("shape", "scale"), [(1.0, 1 / 0.37), (1.0, 0.01), (0.5, 2.0),
                                              (1.5, 3.0), (3.3, 10.0)])
def test_weibull_and_exponential_match_scipy(shape: float, scale: float) -> None:
    x = np.arange(0.0, 400.0)
    ours = WeibullX(shape, scale)
    ref = st.expon(scale=scale) if shape == 1.0 else st.weibull_min(shape, scale=scale)
    for name in ("cdf", "sf"):
        a, b = getattr(ours, name)(x), getattr(ref, name)(x)
        keep = b >= 1e-300
        assert _rel(a[keep & (b > 0)], b[keep & (b > 0)]) <= 1e-13, name
    assert np.array_equal(ours.sf(x), ref.sf(x))  # exp(-y): the same formula, the same bits
    lr = ref.logsf(x)
    assert np.array_equal(ours.logsf(x)[1:], lr[1:])


@pytest.mark.parametrize(("ours", "scipy_law"), [
    (lambda: D.poisson(2.0), lambda: D.scipy_discrete("poisson", 2.0)),
    (lambda: D.poisson(7.5), lambda: D.scipy_discrete("poisson", 7.5)),
    (lambda: D.exponential(0.37), lambda: D.discretised("expon", 0.0, 1 / 0.37)),
    (lambda: D.weibull(1.5, 3.0), lambda: D.discretised("weibull_min", 1.5, 0.0, 3.0)),
])
def test_first_occurrence_laws_match_scipy_route(ours, scipy_law) -> None:
    """The laws the automaton reads: pmf, survival and hazard at the steps up to the
    truncation point, against the same law built on scipy.stats; the hazard is a
    quotient of two such values (relative 1e-12); the decided points are the same."""
    new, old = ours(), scipy_law()
    end = old.truncation_point(1e-12)
    k = np.arange(0, end + 2)
    for name, tol in (("pmf", 1e-13), ("cdf", 1e-13), ("survival", 1e-13), ("hazard", 1e-12)):
        a, b = getattr(new, name)(k), getattr(old, name)(k)
        keep = b > 0
        assert _rel(a[keep], b[keep]) <= tol, name
        assert np.array_equal(a[~keep], b[~keep]), name
    assert new.truncation_point(1e-12) == end
    assert new.truncation_point(1e-6) == old.truncation_point(1e-6)
    assert new.constant_hazard_from == old.constant_hazard_from
    assert new.never == old.never == 0.0


def test_corridor_bracket_contains_the_scipy_law_answer() -> None:
    """The bundled corridor model file (a Poisson door) solved with the closed form and
    with the law built on scipy.stats (the route before): the certified brackets agree
    but for the last bits the laws moved, so each holds the other's ends to 1e-12."""
    pytest.importorskip("stormpy")
    from mitld_lp import load_model, synthesize

    model = load_model(ROOT / "models" / "corridor.toml")
    new = synthesize(model)
    old = synthesize(dataclasses.replace(
        model, distributions={e: D.scipy_discrete("poisson", 2.0) for e in model.distributions}))
    assert new.certified and old.certified
    assert new.lower <= old.lower + 1e-12 and old.upper - 1e-12 <= new.upper
    assert abs(new.lower - old.lower) <= 1e-12 and abs(new.upper - old.upper) <= 1e-12
    assert new.lower < new.upper  # the door's law is truncated: a true interval


def test_spec_parsed_once_on_a_prism_model_file(monkeypatch: pytest.MonkeyPatch) -> None:
    """The PRISM table reads the spec for the loader's decided states and the file for
    its task: one parse (lark) for both."""
    pytest.importorskip("stormpy")
    from mitld_lp import game_tables, load_model

    game_tables._checked.cache_clear()
    calls = []
    real = game_tables.parse_source
    monkeypatch.setattr(game_tables, "parse_source",
                        lambda text: calls.append(text) or real(text))
    load_model(ROOT / "models" / "corridor.toml")
    assert calls == ["D[door] opened & F[0,7] goal"]
    with pytest.raises(Exception, match="spec"):  # a failure is not kept: it raises again
        from mitld_lp import loads_model
        loads_model('name = "x"\nspec = "F ("\n[grid]\nsize = [2, 2]\nstart = [0, 0]\n')


_PROBE = """
import sys, pathlib, tempfile
from mitld_lp import load_model, synthesize
model = sys.argv[1]
if model == "no-law":
    folder = pathlib.Path(tempfile.mkdtemp())
    (folder / "m.toml").write_text(
        'name = "c"\\nspec = "F[0,7] goal"\\n[prism]\\nfile = "%s"\\n'
        'constants = { open_at_start = true }\\n' % (sys.argv[2],))
    model = folder / "m.toml"
r = synthesize(load_model(model))
assert r.certified
print(" ".join(sorted(sys.modules)))
"""


@pytest.mark.parametrize("which", ["no-law", "poisson"])
def test_prism_solve_imports_none_of_the_lazy_modules(which: str) -> None:
    pytest.importorskip("stormpy")
    args = (["no-law", str(ROOT / "models" / "corridor.prism")] if which == "no-law"
            else [str(ROOT / "models" / "corridor.toml")])
    done = subprocess.run([sys.executable, "-c", _PROBE, *args], capture_output=True,
                          text=True, timeout=300, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    loaded = set(done.stdout.split())
    assert "mitld_lp.synthesis" in loaded  # the probe did solve
    for lazy in ("scipy.stats", "mitld_lp.worlds.grid", "mitld_lp.distributions.closed",
                 "mitld_lp.util.watch", "mitld_lp.distributions.weibull_law"):
        assert lazy not in loaded, lazy
    assert ("mitld_lp.distributions.poisson_law" in loaded) == (which == "poisson")


def test_lazy_package_names_keep_the_public_api() -> None:
    from mitld_lp.distributions import FirstOccurrence, from_table, poisson
    from mitld_lp.logic import Verdict, holds, holds_lasso

    assert callable(poisson) and poisson(2).label == "poisson(2)"
    assert isinstance(from_table({"poisson": 2}, "d"), FirstOccurrence)
    assert callable(holds) and callable(holds_lasso) and isinstance(Verdict, type)
    import mitld_lp.distributions as dpkg
    import mitld_lp.logic as lpkg

    assert set(dpkg.__all__) <= set(dir(dpkg)) and set(lpkg.__all__) <= set(dir(lpkg))
    assert all(getattr(dpkg, n) is not None for n in dpkg.__all__)
    with pytest.raises(AttributeError):
        dpkg.no_such_name  # noqa: B018

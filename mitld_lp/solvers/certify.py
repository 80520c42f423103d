r"""Brackets that hold in exact arithmetic: the certificate of a solved model.

The solvers compute in floating point on the product's stored probabilities ``p^``;
the model as written has exact (rational) probabilities ``p`` with
``|p^ - p| <= eta * p`` entry by entry (:data:`ETA`, :func:`model_eta`) and the same
support.  Whatever the solvers did, a bound reported here is the conclusion of
inequalities checked on the float vectors with every rounding accounted for, so it
holds for the exact model:

* **a lower bound on a policy's value** (``policy_lower``): a vector ``L`` with
  ``L = 1`` where the policy's chain reaches the target almost surely, ``L = 0`` where
  it cannot reach it (both from the chain's graph), and ``L(s) <= E_sigma(s)(L)``
  elsewhere, checked with the float sum rounded down.  On those states the chain is
  transient, so ``(I - P) (L - v) <= 0`` gives ``L <= v``;
* **an upper bound on a policy's value** (``policy_upper``): ``U >= E_sigma(s)(U)``
  rounded up; the policy's value is the chain's least fixed point, so ``U >= v``;
* **an upper bound on the maximum** (``optimum_upper``): ``U = 1`` on the target and
  ``E_c(U) <= U(s)`` for every state and choice, rounded up; the maximum is the least
  fixed point of the Bellman operator, so ``U >= Pmax`` (a choice whose support has
  ``max_j U(j) <= U(s)`` passes without arithmetic: a convex combination);
* **a lower bound on the minimum** (``optimum_lower``): ``L = 0`` on the states from
  which some policy avoids the target for ever (given, and checked to leave no end
  component outside them), ``L(s) <= E_c(L)`` for every choice, rounded down; with no
  end component left the minimum is the operator's only fixed point there, so
  ``L <= Pmin``.

The float sums are bounded by :mod:`mitld_lp.solvers.rounding`.

The candidates are built with slack so that the checks pass at relative precision:
from the policy's float values ``v`` (one more solve with each block's LU:
``W = (I - P)^{-1} (delta * v)``, ``delta`` twice each state's measured relative
residual plus its rounding bound), ``L = v - W`` and ``U = v + W``: then
``(I - P) L = b + r - delta v``, below the target's mass by ``delta v - r > 0`` in
every state, and ``W(s) / v(s)`` is ``delta`` times the expected steps to the target
(conditioned on reaching it): the bracket's relative width.  A check that still fails
is retried with a larger slack, then repaired (a failing state's bound moved to what
its choices need, downstream first, the states of an end component together), then
the iteration's bound is tried, and last a trivial bound (0 or 1) that always holds:
the answer is then sound but not precise, and its check says so.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.checks import Check
from mitld_lp.mdp import MDP
from mitld_lp.solvers.analysis import end_components
from mitld_lp.solvers.certify_chain import (
    Chain,
    RowModel,
    chain,
    escapes,
    full_values,
    support_layers,
)
from mitld_lp.solvers.certify_compiled import compiled_checks, compiled_failing, load_if_warm
from mitld_lp.solvers.certify_everywhere import EVERYWHERE, EVERYWHERE_BATCH, everywhere
from mitld_lp.solvers.certify_policy import (
    GROWTH,
    RETRIES,
    Side,
    policy_lower,
    policy_upper,
    scales,
)
from mitld_lp.solvers.certify_repair import (
    ROUNDS,
    SPARSE_LEVEL,
    Repair,
    Rows,
    repair_levels,
)
from mitld_lp.solvers.chain_levels import forget
from mitld_lp.solvers.result import Lifted, read_only
from mitld_lp.solvers.rounding import (
    ETA,
    HAZARD_ACCURACY,
    UNIT,
    Rounding,
    above,
    below,
    float_down,
    float_up,
    model_eta,
    one_minus,
    range_extreme,
    rounding,
    support_extreme,
)
from mitld_lp.solvers.rows import gather_ranges, row_entries, rows_dot
from mitld_lp.util.heap import release_free_memory
from mitld_lp.util.sparsetools import sparsetools

__all__ = ["ETA", "UNIT", "HAZARD_ACCURACY", "Rounding", "rounding", "below", "above",
           "Chain", "chain", "RowModel", "support_layers", "Side", "Certificate", "certify",
           "everywhere", "policy_lower", "policy_upper", "optimum_upper", "optimum_lower",
           "model_eta", "float_down", "float_up", "one_minus", "EVERYWHERE",
           "EVERYWHERE_BATCH", "ROUNDS", "SPARSE_LEVEL", "is_certificate_check", "GROWTH",
           "RETRIES"]

log = logging.getLogger(__name__)

_LOWER_OPTIMUM = "lower bound: the optimum"  # the name of :func:`optimum_lower`'s check

BATCH = 1 << 14
"""Rows the NumPy Bellman check reads at a time (:func:`_fails`; its temporaries,
some 70 bytes a row: its memory bound, not its verdicts)."""

SPARSE_SUSPECTS = 8
"""A batch of the Bellman checks reads the support's extreme from its whole slice of
the matrix (:func:`~mitld_lp.solvers.rounding.range_extreme`) when at least one row in
this many fails the arithmetic, else from the failing rows' entries
(:func:`~mitld_lp.solvers.rounding.support_extreme`): the same extremes either way."""


def is_certificate_check(check: Check) -> bool:
    """Whether ``check`` is one of a model's certificate checks (a bound or
    :func:`everywhere`): what an exact answer proves in their place."""
    return check.name.startswith(("lower bound: ", "upper bound: ")) or \
        check.name == EVERYWHERE


# ------------------------------------------------------------------ the Bellman checks


def _direct(m: sp.csr_array, x: np.ndarray) -> bool:
    """Whether :func:`_fails` may hand a batch of ``m``'s rows to SciPy's compiled CSR
    product by their pointers into the whole matrix (``m[a:z] @ x`` calls the same
    kernel on a copy of those rows: each row's sum from 0 in its entries' order, the
    same bits) rather than slice them: float64 values and vector, one index type."""
    return (sparsetools is not None and m.data.dtype == np.float64 and x.dtype == np.float64
            and x.ndim == 1 and x.flags.c_contiguous and m.indptr.dtype == m.indices.dtype
            and m.indices.dtype in (np.int32, np.int64)
            and x.shape[0] == m.shape[1])


def _fails(st: Rows, rnd: Rounding, x: np.ndarray, free: np.ndarray,
           upper: bool) -> np.ndarray:
    """The states (not ``free``) where some choice breaks the pre- (``upper``) or
    sub-fixed point inequality, rounding and the convex rule accounted for (a robust
    choice passes when one of nature's rows does).  From the repair's needs where
    compiled (:func:`~mitld_lp.solvers.certify_compiled.compiled_failing`: the same
    verdicts, and the repair's kernel the only one a certificate's check links)."""
    failing = compiled_failing(st, rnd, x, free, upper=upper)
    if failing is not None:
        return failing
    ok = compiled_checks(st, rnd, x, free, upper)  # one compiled pass, where paid
    if ok is None:
        ok = numpy_checks(st, rnd, x, free, upper)
    if st.nature is not None:
        ok = np.logical_or.reduceat(ok, st.nature[:-1])
    return ~np.logical_and.reduceat(ok, st.groups[:-1])


def numpy_checks(st: Rows, rnd: Rounding, x: np.ndarray, free: np.ndarray,
                  upper: bool) -> np.ndarray:
    """Per row of ``st.matrix``: whether it passes :func:`_fails`'s check, by NumPy."""
    m = st.matrix
    ok = np.empty(m.shape[0], dtype=bool)
    direct = _direct(m, x)
    rule = _rule_values(x, upper)
    # :data:`BATCH` rows at a time (slices: the rounding's own arrays, not
    # gathered copies), each batch's states found from the groups (no state a row of
    # the whole matrix): the float arrays of every row at once were the certificate's
    # peak on QVBS wlan_dl; each row's sum is the same (scipy sums a row in its
    # entries' order)
    for a in range(0, m.shape[0], BATCH):
        z = min(a + BATCH, m.shape[0])
        row_state = st.row_states(a, z)
        if direct:  # SciPy's product kernel on the rows' pointers, no copy of the rows
            sums = np.zeros(z - a)
            sparsetools.csr_matvec(z - a, x.shape[0], m.indptr[a:z + 1], m.indices, m.data, x,
                           sums)
        else:
            sums = m[a:z] @ x
        ok[a:z] = _rows_pass(m, rnd, x, slice(a, z), sums, x[row_state], upper, rule)
        ok[a:z] |= free[row_state]
        del sums, row_state
    return ok


def _rows_pass(m: sp.csr_array, rnd: Rounding, x: np.ndarray, rows: np.ndarray | slice,
               sums: np.ndarray, own: np.ndarray, upper: bool,
               rule: tuple[float | None, float | None, np.ndarray | None]) -> np.ndarray:
    """Per row of ``rows`` (a slice of the matrix's rows, or their indices), with its
    float sum ``sums`` and its state's value ``own``: whether it passes the check of
    :func:`_fails`, by the rounded sum or by the convex rule (the extreme of ``x`` over
    the row's support against ``own``).  Most rows the arithmetic does not pass (QVBS
    products: those of the states at 1 and at 0) are settled by ``x``'s own extremes
    (``rule``, :func:`_rule_values`); the rest read their supports."""
    bound = above(rnd, rows, sums) if upper else below(rnd, rows, sums)
    good = (bound <= own) if upper else (bound >= own)
    miss = np.flatnonzero(~good)
    top, bottom, past = rule
    sliced = isinstance(rows, slice)
    at = (lambda k: k + rows.start) if sliced else (lambda k: rows[k])  # noqa: E731
    if miss.size and top is not None:
        at_top = own[miss] == top  # the support's extreme is within ``x``'s range
        good[miss[at_top]] = True
        miss = miss[~at_top]
        at_bottom = own[miss] == bottom
        if past is not None and at_bottom.any():
            # no stored successor past ``bottom``
            low = miss[at_bottom]
            if sliced:
                good[low] = ~_reaching(m, rows.start, rows.stop, past, low)
            else:
                local, cols, _ = row_entries(m, at(low))
                reached = np.zeros(low.size, dtype=bool)
                reached[local[past[cols]]] = True
                good[low] = ~reached
                del local, cols, reached
            miss = miss[~at_bottom]
    if sliced and miss.size * SPARSE_SUSPECTS >= own.size:
        ext = range_extreme(m, rows.start, rows.stop, x, largest=upper)[miss]
    elif miss.size:
        ext = support_extreme(m, at(miss), x, largest=upper)
    else:
        return good
    good[miss] = (ext <= own[miss]) if upper else (ext >= own[miss])
    return good


def _fails_among(st: Rows, rnd: Rounding, x: np.ndarray, free: np.ndarray, upper: bool,
                 states: np.ndarray) -> np.ndarray:
    """:func:`_fails` on the ``states`` (a mask; each with a choice) alone, every other
    state reported passing: for a candidate whose other states passed :func:`_fails`
    with every value their rows read the same, so that their rows' checks are the same
    computations, with the same outcome (:func:`_touched`)."""
    m = st.matrix
    among = np.flatnonzero(states)
    failing = compiled_failing(st, rnd, x, free, among, upper)  # as :func:`_fails`
    if failing is not None:
        return failing
    rows, choice_starts, state_starts = st.rows_of(among)
    good = compiled_checks(st, rnd, x, free, upper, among)
    if good is None:
        per_row = np.diff(np.append(state_starts if choice_starts is None else
                                    choice_starts[state_starts], rows.size))
        own_state = np.repeat(among, per_row)
        good = _rows_pass(m, rnd, x, rows, rows_dot(m, rows, x), x[own_state], upper,
                          _rule_values(x, upper))
        good |= free[own_state]
    if choice_starts is not None:
        good = np.logical_or.reduceat(good, choice_starts)
    failing = np.zeros(st.n_states, dtype=bool)
    failing[among] = ~np.logical_and.reduceat(good, state_starts)
    return failing


def _touched(st: Rows, changed: np.ndarray,
             readers_of: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray:
    """The states whose check can differ once the ``changed`` states' values moved:
    those, and those with a row holding one of them (the other rows read the same
    values, so their sums and their states' values are the same).  ``readers_of``: the
    matrix's pattern by column as each entry's state, where the repair made it
    (:func:`~mitld_lp.solvers.certify_repair.readers_by_column`; then only the changed
    states' columns are read)."""
    out = changed.copy()
    if readers_of is not None:
        col_ptr, col_state = readers_of
        moved = np.flatnonzero(changed)
        out[col_state[gather_ranges(col_ptr[moved], col_ptr[moved + 1])]] = True
        return out
    m = st.matrix
    hit = changed[m.indices]
    filled = np.diff(m.indptr) > 0
    reads = np.zeros(m.shape[0], dtype=bool)
    if hit.size:
        reads[filled] = np.logical_or.reduceat(hit, m.indptr[:-1][filled])
    out[st.row_state()[reads]] = True
    return out


def _reaching(m: sp.csr_array, a: int, z: int, past: np.ndarray,
              among: np.ndarray) -> np.ndarray:
    """Per row ``a + among[i]`` of the consecutive rows ``a:z``: whether a stored
    entry's column is ``past`` (False on an empty row), from one slice of the matrix's
    arrays as :func:`~mitld_lp.solvers.rounding.range_extreme` reads them: the count of
    such entries before each row's end and start (a running sum over the slice, exact
    in integers; a segmented ``reduceat`` took three times as long)."""
    ptr = m.indptr
    ea, ez = int(ptr[a]), int(ptr[z])
    if ez == ea:
        return np.zeros(among.size, dtype=bool)
    seen = np.zeros(ez - ea + 1, dtype=np.int32 if ez - ea < 2**31 - 1 else np.int64)
    np.cumsum(past[m.indices[ea:ez]], out=seen[1:])
    return seen[ptr[a + 1 + among] - ea] > seen[ptr[a + among] - ea]


def _rule_values(x: np.ndarray, upper: bool
                 ) -> tuple[float | None, float | None, np.ndarray | None]:
    """What settles the convex rule of :func:`_fails` without reading a row's support,
    from ``x``'s extremes ``lo`` and ``hi`` (finite: else ``(None, None, None)``, every
    support read): ``top``, the own value at which the rule holds for every row (an
    upper check's ``hi``: the largest ``x`` over a support is at most ``hi``; a lower
    check's ``lo``); ``bottom``, the own value at which it holds exactly when no
    successor is past it (an upper check's ``lo``: no successor above ``lo``); and
    ``past``, the states past ``bottom`` (a bool a state: it was a float a state, 1.0
    on them, for SciPy's product, 4.4 bytes a transition at QVBS csma 4-2's Bellman
    check), so that a row passes there exactly when no stored entry's column is past:
    the support's extreme against ``bottom``, the same verdict."""
    if x.size == 0:
        return None, None, None
    lo, hi = float(np.min(x)), float(np.max(x))
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return None, None, None
    top, bottom = (hi, lo) if upper else (lo, hi)
    return top, bottom, (x > bottom) if upper else (x < bottom)


def _optimum_side(st: Rows, initial: int, ch: Chain, rnd: Rounding, *, upper: bool,
                  zero: np.ndarray, one: np.ndarray | None, fallback: np.ndarray | None,
                  layers: tuple[np.ndarray, np.ndarray], mec_of: np.ndarray | None,
                  name: str) -> Side:
    target = ch.target
    # a lower bound may be 0 anywhere; an upper bound's 0 on ``zero`` is a candidate,
    # checked like every other value (the graph's word is not taken on trust)
    free = target | zero if not upper else target.copy()

    def base() -> np.ndarray:
        # made for each candidate, not held beside it (a float a state): the
        # certificate's peak on QVBS wlan_dl
        x = np.where(target, 1.0, 0.0)
        if one is not None:
            x[one] = 1.0
        return x

    def candidate(scale: float) -> np.ndarray:
        x = base()
        idx = ch.solved & ~free
        kept = ~free[ch.solved]  # (``v`` and ``w`` are the solved states', in their order)
        v, w = ch.v[kept], ch.w[kept]
        del kept
        if upper:
            x[idx] = np.minimum(v + scale * w, 1.0)
            x[ch.sure & ~free] = 1.0
            rest = ch.never & ~free
            x[rest] = 1.0 if fallback is None else np.minimum(fallback[rest] * 1.0000001, 1.0)
            x[zero & ~free] = 0.0
        else:
            x[idx] = np.maximum(v - scale * w, 0.0)
            x[ch.sure & ~free] = 1.0
            x[ch.never & ~free] = 0.0
        return x

    tried = []
    # the end components the repair moves together (none: nothing to gather)
    mecs = mec_of if upper and mec_of is not None and bool(np.any(mec_of >= 0)) else None
    candidates = [(f"slack x{s:g}", lambda s=s: candidate(s)) for s in scales()]
    if fallback is not None:
        def from_iteration() -> np.ndarray:
            x = candidate(scales()[-1])
            f = fallback if isinstance(fallback, Lifted) else np.asarray(fallback,
                                                                         dtype=np.float64)
            live = ~free
            if upper:
                x[live] = np.minimum(np.maximum(x[live], f[live] * (1.0 + 2.0**-30)), 1.0)
            else:
                x[live] = np.maximum(np.minimum(x[live], f[live] * (1.0 - 2.0**-30)), 0.0)
            return x
        candidates.append(("the iteration's bound", from_iteration))
    level_of = None  # each state's level, made when a candidate first needs a repair
    last = None  # the last repair: its pattern by column and end components' members
    for label, make in candidates:
        x = make()
        failing = _fails(st, rnd, x, free, upper)
        moved = 0
        if failing.any():
            if level_of is None:
                level_of = np.asarray(layers[1])[np.asarray(layers[0])]
            level_of, held = repair_levels(st, level_of, x, free, zero if upper else None)
            # what a repair reads of the model alone, made once for every candidate
            # (bus_scaled n128 d3: two candidates repaired, each transposed the pattern)
            repair = last = Repair(st, rnd, held, level_of, mecs, upper,
                                    members=None if last is None else last.members,
                                    readers_of=None if last is None else last.readers_of)
            before = x.copy()
            closed = repair.run(x, failing & ~held) if bool(np.any(failing & ~held)) \
                else False
            moved = repair.moved
            if not closed:
                tried.append(f"{label}: {int(failing.sum())} states, repair did not close")
                continue
            # checked again where a value it reads moved, and where it failed: the rest
            # passed just now on the same values (:func:`_fails_among`)
            again = _touched(st, x != before, repair.readers_of) | failing
            del before
            # (a state without a choice, or a choice without nature's rows, is left to
            # the whole check: its verdict there reads the next row's)
            failing = (_fails_among(st, rnd, x, free, upper, again)
                       if bool(np.all(np.diff(st.groups)[again] > 0)) and (
                           st.nature is None or bool(np.all(np.diff(st.nature) > 0)))
                       else _fails(st, rnd, x, free, upper))
            if failing.any():
                tried.append(f"{label}: {int(failing.sum())} states after the repair")
                continue
        return Side(float(x[initial]), Check(name, True, (
            f"{'pre' if upper else 'sub'}-fixed point of the Bellman operator checked in "
            f"exact arithmetic on {int((~free).sum())} states and every choice "
            f"({label}, eta {rnd.eta:.2g}" + (f", {moved} states repaired" if
                                               moved else "")
            + f"): {float(x[initial])!r}")), read_only(x))
    x = base()
    x[~free] = 1.0 if upper else 0.0
    return Side(float(x[initial]), Check(name, False, (
        "no candidate passed (" + "; ".join(tried) + f"); the bound is the trivial "
        f"{x[initial]:g}")), read_only(x))


def optimum_upper(mdp: MDP, ch: Chain, rnd: Rounding, *, zero: np.ndarray,
                  layers: tuple[np.ndarray, np.ndarray], mec_of: np.ndarray | None = None,
                  fallback: np.ndarray | None = None, nature: np.ndarray | None = None,
                  ) -> Side:
    """An upper bound on the maximal probability of reaching the target (module docs).
    ``zero``: the states from which no policy reaches it (the candidate's 0 there is
    checked like every other value: a choice whose support stays in them passes);
    ``mec_of``: the maximal end components (their states' bounds are moved together by
    the repair); ``fallback``: an upper vector to
    try when the policy's does not pass (the iteration's).  ``nature``: for a robust
    game, each choice's rows (``mdp.matrix``'s rows are then nature's vertex rows and
    ``mdp.row_groups`` group the choices): the bound is on ``max_c min_rows``, the
    robust optimum, and ``ch`` is the chain of the policy against nature's strategy."""
    st = Rows(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64), nature)
    return _optimum_side(st, int(mdp.initial), ch, rnd, upper=True,
                         zero=np.asarray(zero, dtype=bool), one=None, fallback=fallback,
                         layers=layers, mec_of=mec_of, name="upper bound: the optimum")


def optimum_lower(mdp: MDP, ch: Chain, rnd: Rounding, *, zero: np.ndarray,
                  layers: tuple[np.ndarray, np.ndarray], one: np.ndarray | None = None,
                  fallback: np.ndarray | None = None, trapped: Side | None = None,
                  checked: bool = False) -> Side:
    """A lower bound on the minimal probability of reaching the target (module docs).
    ``zero``: the states from which some policy avoids the target for ever (checked:
    no end component may remain outside it and the target, else the bound is 0);
    ``one``: the states from which every policy reaches it (a candidate value of 1,
    checked); ``fallback``: a lower vector to try (the iteration's).  ``checked``: that
    check was made before, its outcome ``trapped`` (:func:`_trapped` of the same model,
    zero set and target: :func:`certify` makes it before the chain, whose vectors are
    not alive then)."""
    zero = np.asarray(zero, dtype=bool)
    if not checked:
        trapped = _trapped(mdp, zero, ch.target, layers)
    if trapped is not None:
        return trapped
    st = Rows(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64))
    return _optimum_side(st, int(mdp.initial), ch, rnd, upper=False, zero=zero, one=one,
                         fallback=fallback, layers=layers, mec_of=None,
                         name=_LOWER_OPTIMUM)


def _trapped(mdp: MDP, zero: np.ndarray, target: np.ndarray,
             layers: tuple[np.ndarray, np.ndarray]) -> Side | None:
    """:func:`optimum_lower`'s trivial bound where an end component lies outside the
    ``zero`` set and the ``target`` (the minimum is then not the operator's only fixed
    point there); None where none does (:func:`_escapes`, else the search)."""
    zero = np.asarray(zero, dtype=bool)
    target = np.asarray(target, dtype=bool)
    left = ~zero & ~target
    comp = np.asarray(layers[0])
    ecs = None if _escapes(mdp, left, comp) else end_components(mdp, comp, left)
    if ecs is None or not ecs.n_mecs:
        return None
    s = int(np.flatnonzero(ecs.mec_of >= 0)[0])
    return Side(0.0, Check(_LOWER_OPTIMUM, False, (
        f"{ecs.n_mecs} end components outside the zero set (state {s}): the minimum "
        "is not the operator's only fixed point there; the bound is the trivial 0")),
        read_only(np.where(target, 1.0, 0.0)))


def _escapes(mdp: MDP, left: np.ndarray, comp: np.ndarray) -> bool:
    """Whether no end component lies among the ``left`` states (``comp``: each state's
    strongly connected component in ``mdp``'s support graph), shown without searching
    for one: none of them may hold one (:func:`~mitld_lp.solvers.analysis.may_cycle`,
    read on their choices alone: :func:`~mitld_lp.solvers.certify_chain.cycling_among`),
    or every policy leaves those that may with positive probability, one
    :func:`~mitld_lp.solvers.graph.attractor` of the other states (and of the states
    with no choice, where a play stops) covering them.  An end component inside ``left``
    keeps its states out of that attractor (each has a choice whose support stays in
    it), so True proves there is none; False leaves the search for the components to
    the caller, as does a matrix that stores a zero (its pattern is more than the
    support).  The attractor is walked on those states' own rows alone
    (:func:`~mitld_lp.solvers.certify_chain.attracted`): the same set there."""
    return escapes(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64),
                   comp, left)


# ------------------------------------------------------------------ one model


@dataclass(frozen=True, slots=True, eq=False)
class Certificate:
    """One model's checked bounds at the initial state: ``lower`` and ``upper`` (``nan``
    for a side not asked), the policy's float ``values`` (every state), the ``checks``."""

    lower: float
    upper: float
    values: np.ndarray
    checks: tuple[Check, ...]

    @property
    def certified(self) -> bool:
        return all(c.passed for c in self.checks)


def certify(mdp: MDP, target: np.ndarray, policy: np.ndarray, *, sense: str = "max",
            sides: tuple[str, ...] = ("lower", "upper"), zero: np.ndarray,
            one: np.ndarray | None = None, mec_of: np.ndarray | None = None,
            layers: tuple[np.ndarray, np.ndarray] | None = None,
            fallback_lower: np.ndarray | None = None,
            fallback_upper: np.ndarray | None = None, eta: float = ETA,
            precision: float | None = None, complement: bool = False,
            trim: bool = False) -> Certificate:
    """The certificate of one solved model (module docs).  ``sense="max"``: ``lower``
    bounds the policy's value, ``upper`` the maximum (``zero``: the states from which
    no policy reaches the target); ``sense="min"``: ``lower`` bounds the minimum
    (``zero``: the states from which some policy avoids the target for ever; ``one``:
    those from which every policy reaches it), ``upper`` the policy's value.
    ``sides``: which bounds to check; ``fallback_*``: the iteration's vectors (arrays, or
    :class:`~mitld_lp.solvers.result.Lifted` read where used).  With
    both sides and a ``precision``, one more check: the policy is within that
    precision of the optimum in every state (:func:`everywhere`; ``complement``: the
    answer is ``1 -`` these values, the precision relative to that).  ``trim``: the
    heap's free pages handed back before that last check (:mod:`mitld_lp.util.heap`):
    the chain's and the sides' freed arrays are holes it does not fill, on QVBS csma 4-2
    some 15 bytes a transition of the solve's resident peak."""
    if sense not in ("max", "min"):
        raise ValueError(f"sense: must be 'max' or 'min', got {sense!r}")
    target = np.asarray(target, dtype=bool)
    rnd = rounding(sp.csr_array(mdp.matrix), eta)
    load_if_warm(int(mdp.matrix.nnz))  # the compiled kernels' load, where cheap
    if layers is None:
        layers = support_layers(mdp)
    # a minimum's end-component check reads no chain: made before it, whose vectors
    # are not alive yet (its walks were the certificate's peak on QVBS csma 4-2)
    checked = sense == "min" and "lower" in sides
    trapped = _trapped(mdp, zero, target, layers) if checked else None
    try:  # the LP's walks offered to the chain (:func:`chain_levels.offer`), then freed
        ch = chain(mdp, target, policy, rnd, layers, guess=fallback_lower)
    finally:
        forget()
    low = high = None
    if "lower" in sides:
        low = (policy_lower(mdp, ch, rnd) if sense == "max" else
               optimum_lower(mdp, ch, rnd, zero=zero, one=one, layers=layers,
                             fallback=fallback_lower, trapped=trapped,
                             checked=checked))
    if "upper" in sides:
        high = (optimum_upper(mdp, ch, rnd, zero=zero, layers=layers, mec_of=mec_of,
                              fallback=fallback_upper) if sense == "max" else
                policy_upper(mdp, ch, rnd))
    # the policy's values on every state made last, once the sides' vectors are
    # freed: a float a state not held beside them through the policy's side and the
    # last check (QVBS csma 4-2's certificate peak), only the solved states' values
    # and two sets as bits; the rounding's counts (an index a row) freed before the
    # last check
    n = int(ch.solved.shape[0])
    solved_values = ch.v
    solved, sure = np.packbits(ch.solved), np.packbits(ch.sure)
    del ch, rnd  # its slack and sets, read by the sides alone: freed before the last check
    if trim:
        release_free_memory()
    checks = [s.check for s in (low, high) if s is not None]
    if low is not None and high is not None and precision is not None:
        checks.append(everywhere(low.vector, high.vector, int(mdp.initial), precision,
                                 complement=complement))
    lower = float("nan") if low is None else low.value
    upper = float("nan") if high is None else high.value
    del low, high
    values = full_values(solved_values, np.unpackbits(solved, count=n).view(bool),
                         np.unpackbits(sure, count=n).view(bool))
    return Certificate(lower, upper, read_only(values), tuple(checks))

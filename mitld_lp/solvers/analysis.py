r"""One graph analysis of a product, shared by both truncation models.

The product is solved twice: its truncated states count as losing (the *lower* model)
and as winning (the *upper* one).  Both models have the same support graph, so one
analysis serves both:

* the **state graph** is a view of the product's matrix (a state's choices are
  consecutive rows, so its successors are a slice of the matrix's column indices): no
  copy;
* one **strongly connected decomposition** of it
  (:func:`~mitld_lp.solvers.graph.components_reaching`), and which states can reach
  the goal and which the goal or a truncated state (a search of the state graph
  reversed where most components are single states, else of the condensation): the
  prob-0 sets of both models (``Pmax = 0`` iff no path).  The components' levels
  (level 0 has no successor component; every edge between components goes down) are
  found on the quotient alone
  (:mod:`~mitld_lp.solvers.quotient_order`), unless the compiled walk gives the
  product's in the same pass;
* the **maximal end components** of the upper model's *maybe* states (neither target
  nor prob-0), searched only among the states of non-trivial components (and single
  states with a choice that stays put): an end component is strongly connected, so it
  lies inside one component (on a large product one attractor pass first shows
  whether there is any: a rare event's product often has none; where every component
  is one state, each maybe state with a choice that stays put is one, found without a
  search).  They are the lower
  model's end components too: an end component's states reach the same states, so it
  lies either wholly among the lower model's maybe states or wholly outside them;
* one **quotient** (:class:`~mitld_lp.solvers.reduced.Quotient`): the upper model's
  maybe states with those end components collapsed, and its matrix, shared by the two
  models, which differ only in the one-step probability of reaching their target.  A
  state of the lower model that can reach a truncated state but not the goal is kept
  in it with its value known to be 0 (``Quotient.zero``): the solvers skip it;
* the **qualitative sets** of each model (:class:`~mitld_lp.solvers.reduced.
  Qualitative`, Storm's *prob01*), from the graph alone: the prob-0 states above, and
  the states of value 1 (``Prob1E``: on the quotient, which has no end component, the
  states with a choice that cannot lose and stays among such states; the complement is
  an :func:`~mitld_lp.solvers.graph.attractor` of the choices that can lose).

For a **minimum** (``sense=Sense.MIN``) the prob-0 states are ``Prob0E``: the states
from which some policy avoids the target for ever, the complement of the
:func:`~mitld_lp.solvers.graph.attractor` of the target.  The states left have no end
component among them (its states could avoid the target for ever), so nothing is
collapsed; a state of the lower model that some policy keeps from the goal, but not
from a truncated state, is kept with value 0 as above.  The states of value 1
(``Prob1A``) are those that cannot reach a prob-0 state before the target.  Those of
the goal's (so of the wider target's too: every policy that reaches the goal almost
surely reaches it) leave the quotient with value 1, as Storm's *prob1* does before any
number: found on the product's pattern before the quotient is made (the maybe states
with no path through maybe states to a prob-0 state, :func:`~mitld_lp.solvers.reach.
reaching_through`: no quotient of the 99% of QVBS csma 4-2's maybe states and 69% of
firewire_dl 3-600's that had value 1 is built and cut), a choice's probability of
entering one joins its one-step probability of the target (the two sums added, as
:func:`_without_one` adds them), and the solvers, the iteration and the LP, work only
on the states whose value is unknown.  Any choice is optimal there (every policy
reaches the target almost surely): the lifted policy plays the first.  A state of value
1 for the wider target only stays (its value still in ``qualitative.one``).

A maximum's value-1 states of the goal (``Prob1E``, so the wider target's too) leave the
quotient the same way, a collapsed end component of them whole (the others renumbered);
there the lifted policy plays an attractor strategy
(:func:`mitld_lp.solvers.quotient.lift_policy`), which reaches the target almost
surely: the one read from the attractor that found them
(:func:`~mitld_lp.solvers.value_one.attractor_strategy`, kept in ``Quotient.shared``),
no second search.  Where no end component is collapsed, or each is one state (a
deadline's self-loops: :mod:`~mitld_lp.solvers.analysis_singles`, their staying choices
counted as hit), they are found on the product before the quotient is made, by one
attractor over the product's own rows where its other states are closed (its targets);
else on the quotient, which is then cut.  The step and cost objectives never
read this quotient (their routes count the steps of such states).

The solvers walk the components in the order the analysis found (``Quotient.order``)
and never decompose the graph again.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDP, as_state_mask
from mitld_lp.solvers.analysis_ends import end_components, ends_and_sure, may_cycle
from mitld_lp.solvers.analysis_gates import attractor_walks, pay_if_warm
from mitld_lp.solvers.analysis_patterns import compact, largest_inside
from mitld_lp.solvers.analysis_reach import fused_components_reaching
from mitld_lp.solvers.analysis_singles import (
    prob1e_on_product,
    prob1e_single_states,
    single_states,
    without_states,
)
from mitld_lp.solvers.analysis_staying import STAYING_STRATEGY, staying_record
from mitld_lp.solvers.graph import (
    EndComponents,
    Sense,
    attractor_spared,
    backward_reachable,
    components_reaching,
    state_levels,
)
from mitld_lp.solvers.quotient_order import crowded, may_split, mixed, quotient_blocks, split
from mitld_lp.solvers.quotient_rows import quotient_rows
from mitld_lp.solvers.reduced import Qualitative, Quotient
from mitld_lp.solvers.result import read_only
from mitld_lp.solvers.rows import gather_ranges
from mitld_lp.solvers.value_one import (
    ATTRACTOR_STRATEGY,
    SureStrategy,
    attractor_strategy,
    choices_of,
    prob1a_first,
    prob1e_first,
)
from mitld_lp.solvers.walks import load_walks
from mitld_lp.util import kernel_loader
from mitld_lp.util.arrays import index_dtype

__all__ = ["ATTRACTOR_STRATEGY", "SureStrategy", "analyse", "end_components", "may_cycle"]


def _sweeps_compiled(m: sp.csr_array, row_groups: np.ndarray, comp: np.ndarray) -> bool:
    """Whether the interval iteration will sweep a block compiled (loading numba): a
    product of at least :data:`~mitld_lp.solvers.kernels.COMPILED_MIN_ENTRIES` entries
    with a component of at least :data:`~mitld_lp.solvers.kernels.
    COMPILED_MIN_BLOCK_ENTRIES` inside it (a level's block holds its components).  A
    guess from the product, not the quotient: a wrong one costs time, never a result."""
    from mitld_lp.solvers import kernels

    if m.nnz < kernels.COMPILED_MIN_ENTRIES:
        return False
    per_state = np.diff(m.indptr[row_groups])
    # a component's entries bound those inside it: most products decide here, a state
    # at a time, before the count over every entry
    if np.bincount(comp, weights=per_state).max(initial=0) < \
            kernels.COMPILED_MIN_BLOCK_ENTRIES:
        return False
    return largest_inside(m, row_groups, comp) >= kernels.COMPILED_MIN_BLOCK_ENTRIES


def _prob0e(m: sp.csr_array, row_groups: np.ndarray, goal: np.ndarray, wide: np.ndarray,
            two: bool) -> tuple[list[np.ndarray], np.ndarray, tuple]:
    """A minimum's prob-0 states for ``goal`` and for ``wide`` (``Prob0E``: outside the
    attractor of each; ``two``: the targets differ, so two attractors) and its maybe
    states (in the wide attractor, outside ``wide``); third, the lift's staying strategy
    on each prob-0 set, read from its attractor's hit choices
    (:func:`~mitld_lp.solvers.analysis_staying.staying_record`)."""
    if two:  # each attractor with its hit choices (NumPy's walk reverses the pattern twice)
        positive, hit_wide = attractor_spared(m, row_groups, wide)
        reach_goal, hit_goal = attractor_spared(m, row_groups, goal)
        zero = [~reach_goal, ~positive]
        return zero, positive & ~wide, staying_record(
            [(zero[0], hit_goal), (zero[1], hit_wide)], row_groups)
    positive, hit = attractor_spared(m, row_groups, wide)
    # the goal lies in the attractor of the wider target: one set for both
    zero = ~positive
    return [zero, zero], positive & ~wide, staying_record([(zero, hit)], row_groups)


def _no_end_components(n: int, n_choices: int) -> EndComponents:
    """The record of no end component (:meth:`~mitld_lp.solvers.end_components.
    EndComponents.none`: read-only views of stride 0, nothing a state or a choice
    allocated; a minimum's quotients hold it from the analysis to the LP)."""
    return EndComponents.none(n, n_choices)


def _one(sense: Sense, matrix: sp.csr_array, row_groups: np.ndarray, zero: np.ndarray,
         leaks: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """``(n_reduced,)`` bool: the reduced states of value exactly 1 in ``sense``, on the
    quotient (no end component), from its pattern, its states known to be 0 (``zero``)
    and the choices that may move to a removed state of value 0 (``leaks``).  A maximum
    is 1 where some choice keeps among such states (the complement: every choice can
    lose, an :func:`~mitld_lp.solvers.graph.attractor`); a minimum where no path leads
    to a state or a choice that can lose (a backward search).  Second, for a maximum,
    the quotient's choices that cannot lose (``(n_choices,)`` bool, those the attractor
    spared: :func:`~mitld_lp.solvers.value_one.attractor_strategy` plays them); None
    for a minimum."""
    if not (zero.any() or leaks.any()):  # nothing can lose: every state is 1
        return (np.ones(row_groups.shape[0] - 1, dtype=bool),
                np.ones(matrix.shape[0], dtype=bool) if sense is Sense.MAX else None)
    if sense is Sense.MAX:
        lose, hit = attractor_spared(matrix, row_groups, zero, leaks)
        return ~lose, ~hit
    n = row_groups.shape[0] - 1
    owner = np.repeat(np.arange(n), np.diff(row_groups))
    seeds = zero.copy()
    seeds[owner[leaks]] = True
    walks = attractor_walks(matrix.nnz)
    if walks is not None:
        return ~walks.backward(matrix.indptr, matrix.indices, row_groups, seeds,
                               np.zeros(matrix.shape[0], dtype=bool), False), None
    entry_owner = np.repeat(owner, np.diff(matrix.indptr))
    return ~backward_reachable(n, entry_owner, matrix.indices, seeds), None


@dataclass(frozen=True, slots=True)
class _Cut:
    """The quotient without its states of value 1 (:func:`_without_one`)."""

    matrix: sp.csr_array
    row_groups: np.ndarray
    choices: np.ndarray  # each kept choice's row in the quotient before
    new_id: np.ndarray  # each reduced state's id after, -1 where removed
    to_goal: np.ndarray
    to_extra: np.ndarray | None
    leaks: list[np.ndarray]


def _without_one(matrix: sp.csr_array, row_groups: np.ndarray, sure: np.ndarray,
                 to: list[np.ndarray | None], leaks: list[np.ndarray]) -> _Cut:
    """The quotient ``matrix`` (choices grouped by ``row_groups``) without its reduced
    states ``sure`` (value 1 in both models: ``Prob1A`` or ``Prob1E`` of the smaller
    target, so of the larger one too) and their choices: the probability of moving into one of them
    joins the one-step probability of reaching the goal (``to[0]``), as a target
    state's does; ``to[1]`` (the truncated states', or None) and ``leaks`` are kept for
    the choices left."""
    keep = ~sure
    new_id = np.full(sure.size, -1, dtype=np.int64)
    new_id[keep] = np.arange(int(keep.sum()))
    states = np.flatnonzero(keep)
    lo, hi = row_groups[states], row_groups[states + 1]
    choices = gather_ranges(lo, hi)
    groups = np.concatenate([[0], np.cumsum(hi - lo)]).astype(np.int64)
    rows = sp.csr_array(matrix[choices])
    into = rows @ sure.astype(np.float64)
    out = ~sure[rows.indices]  # the entries that stay among the kept states
    per_row = np.bincount(np.repeat(np.arange(choices.size), np.diff(rows.indptr))[out],
                          minlength=choices.size)
    index = rows.indices.dtype
    indptr = np.concatenate([[0], np.cumsum(per_row)])
    cut = sp.csr_array((rows.data[out], new_id[rows.indices[out]].astype(index),
                        indptr.astype(index)), shape=(choices.size, states.size))
    return _Cut(cut, groups, choices, new_id, to[0][choices] + into,
                None if to[1] is None else to[1][choices], [k[choices] for k in leaks])


def _fewer_components(mecs: EndComponents, new_id: np.ndarray, sure: np.ndarray,
                      n_plain: int, mdp: MDP) -> EndComponents:
    """``mecs`` without the end components whose reduced state (``n_plain`` + id) left
    the quotient (``sure``), the others numbered as their reduced states now are (in
    the same order): a removed component's members and internal choices are no longer
    any component's."""
    if bool(np.all(sure[n_plain:])):  # none left: the record of none (stride-0 views)
        return _no_end_components(mecs.mec_of.size, mecs.internal.size)
    kept_plain = int(np.count_nonzero(~sure[:n_plain]))
    renumber = new_id[n_plain:] - kept_plain  # -1 - kept_plain where removed
    renumber[sure[n_plain:]] = -1
    mec_of = np.asarray(mecs.mec_of)
    inside = mec_of >= 0
    new_of = np.where(inside, renumber[np.maximum(mec_of, 0)], -1).astype(mec_of.dtype)
    internal = np.array(mecs.internal, dtype=bool)
    was = np.flatnonzero(internal)
    internal[was[new_of[mdp.state_of(was)] < 0]] = False
    return EndComponents(read_only(new_of), read_only(internal),
                         int(np.count_nonzero(~sure[n_plain:])))


def analyse(mdp: MDP, goal: np.ndarray, extra: np.ndarray | None = None, *,
            sense: Sense = Sense.MAX, without_one: bool = True,
            ) -> tuple[Quotient, Quotient]:
    """The quotients for reaching ``goal`` and for reaching ``goal | extra`` (module
    docs), from one analysis, sharing their matrix, end components and block order,
    for the optimum in ``sense``.  With ``extra`` None or empty both are the same
    object.  ``without_one``: the goal's states of value 1 leave the quotient (module
    docs); False keeps them, as :func:`mitld_lp.solvers.quotient.reduce` does."""
    goal = as_state_mask(mdp, goal, "goal")
    extra = np.zeros_like(goal) if extra is None else as_state_mask(mdp, extra, "extra")
    extra = extra & ~goal
    sense = Sense(sense)
    m = sp.csr_array(mdp.matrix)
    if m.nnz and not bool(np.all(m.data > 0)):  # a zero entry is not an edge
        m = m.copy()
        m.eliminate_zeros()
        mdp = replace(mdp, matrix=m)
    wide = goal | extra
    # nothing truncated: one target, so one seed set, one reach and one set of leaks
    # (the second model's columns are the first's)
    same = not extra.any()
    # a minimum's Prob0E (the attractors of its targets) first: its reversed choices
    # (NumPy's walk) are freed before the state graph's reversal is made, which the
    # minimum's Prob1A reads; and its Prob1A (value_one) right after the components,
    # so that the reversal is freed before the rest of the analysis (csma 4-2: the two
    # were alive together at the analysis's peak, then the reversal beside the sweeps'
    # gate and the components' checks)
    minimum = sense is Sense.MIN
    j0 = 1 if same else 0
    # the load the certificate of this product pays, paid first where its kernels are
    # warm: the walks below run compiled (analysis_gates)
    pay_if_warm(int(m.nnz))
    staying: tuple = ()  # a minimum's staying strategies (analysis_staying)
    if minimum:
        *attracted, staying = _prob0e(m, mdp.row_groups, goal, wide, extra.any())
    # the product's components and reach; its levels only where the walk gives them
    # free (compiled): else the quotient's own are found below
    # (one compiled pass where warm, a minimum's Prob1A search in it: analysis_reach)
    seeds = np.column_stack([goal] if same else [goal, wide])
    fused = fused_components_reaching(m, mdp.row_groups, seeds,
                                      attracted[0][j0] if minimum and without_one else None)
    found, reach, back, crowd = (*components_reaching(m, mdp.row_groups, seeds), None) \
        if fused is None else fused
    del seeds, fused
    reach = reach[:, [0, 0] if same else [0, 1]]
    n = mdp.n_states
    sure_state = np.zeros(n, dtype=bool)
    early = None  # a maximum's value-1 states found with its end components
    if minimum:
        prob0, maybe = attracted
        del attracted
        mecs = _no_end_components(n, mdp.n_choices)
        # the goal's value-1 states out of the quotient, found on the pattern before it
        # is made (value_one): Prob1A on the reversal, then freed
        if without_one:
            sure_state = prob1a_first(m, mdp.row_groups, maybe, prob0[j0], back)
    del back
    if not kernel_loader.compiled_paid() and _sweeps_compiled(m, mdp.row_groups,
                                                               found.component):
        kernel_loader.prepare()  # the loader's pieces, else numba (without PyYAML)
        load_walks()  # the sweeps will load them: the walks below run compiled too
    if crowd is None:  # the only states the components' tests read (else the fused pass's)
        crowd = crowded(found.component)
    if not minimum:
        prob0 = [~reach[:, 0] & ~goal, ~reach[:, 1] & ~wide]
        maybe = reach[:, 1] & ~wide
        # every component one state: no count of them there (crowd is empty iff so)
        one_each = bool(found.component.size) and not crowd.size
        # with the goal's value-1 states where none (their attractor first: analysis_ends)
        mecs, early = ends_and_sure(mdp, found.component, maybe, prob0[j0], one_each) \
            if without_one else (end_components(mdp, found.component, maybe, one_each), None)
    if found.level is None and mixed(found.component, maybe, crowd):  # the order as before
        found = replace(found, level=found.later())
    if found.level is not None or not may_split(found.component, maybe, crowd):
        found = replace(found, later=None)  # the condensation freed (csma: 14 B/t)
    # a maximum's Prob1E where no end component, or only single states, are collapsed,
    # found on the pattern before the quotient is made (value_one, analysis_singles;
    # else on the quotient below, _without_one cutting them out)
    shared: dict = {}  # the quotients' walks, gathered once (Quotient.shared)
    if minimum and staying:  # the lift's choices on the prob-0 states (analysis_staying)
        shared[STAYING_STRATEGY] = staying
    del staying
    if without_one and not minimum and (not mecs.n_mecs or single_states(mecs)):
        # with end components of one state each (a deadline's self-loops) too: their
        # staying choices hit from the start, the components of value 1 dropped
        # (analysis_singles), so no quotient of every maybe state is built and cut
        got = early if early is not None else prob1e_on_product(mdp, m, maybe, prob0[j0],
                                                                mecs)
        first = prob1e_first if not mecs.n_mecs else prob1e_single_states
        sure_state, played = got if got is not None else first(mdp, m, maybe, prob0[j0],
                                                                mecs)
        del got
        if played is not None:
            shared[ATTRACTOR_STRATEGY] = played
        del played
        if mecs.n_mecs:
            mecs = without_states(mecs, sure_state, mdp)
    maybe = maybe & ~sure_state
    if found.level is None and found.later is not None and \
            split(found.component, maybe, sure_state, crowd):
        # the product's levels the layers read (quotient_blocks: a component split by
        # the value-1 states, final here: none is cut below where some are found above),
        # walked before the quotient's rows, its condensation freed (zeroconf 1000-4)
        found = replace(found, level=found.later(), later=None)
    plain = maybe & (mecs.mec_of < 0) if mecs.n_mecs else maybe
    n_plain = int(plain.sum())
    # each state's reduced state and each kept choice's product choice, the quotient's
    # two per-state / per-choice index arrays, kept by both models: int32 where the
    # product's size allows (half the bytes), int64 past 2**31 - 1 (index_dtype)
    state_map = np.full(n, -1, dtype=index_dtype(n))
    state_map[plain] = np.arange(n_plain)
    if mecs.n_mecs:  # none: no mask a state of the stride-0 record read
        in_mec = mecs.mec_of >= 0
        state_map[in_mec] = n_plain + mecs.mec_of[in_mec]
        del in_mec
    n_red = n_plain + mecs.n_mecs

    # the maybe states' choices read from their ranges (no array a choice of the whole
    # product: most products keep a third to two thirds of their choices), ascending
    kept, owner = choices_of(np.asarray(mdp.row_groups), np.flatnonzero(maybe))
    if mecs.n_mecs:  # no internal choice where no end component
        inside = mecs.internal[kept]
        if inside.any():
            kept, owner = kept[~inside], owner[~inside]
        del inside
        by_state = np.argsort(state_map[owner], kind="stable")
        kept, owner = kept[by_state], owner[by_state]
        del by_state
    kept = kept.astype(index_dtype(mdp.n_choices), copy=False)
    counts = np.bincount(state_map[owner], minlength=n_red)
    del owner
    row_groups = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    index = np.int32 if n_red < 2**31 and m.nnz < 2**31 else np.int64
    # The kept rows of the product read a slice at a time into the quotient's arrays
    # (quotient_rows: each entry's column a reduced state, in the index type), with one
    # pass for both targets' one-step probabilities and each model's removed states of
    # value 0 (a choice that may move there can lose): each row's sum in its stored
    # order, as over the whole product.  Two columns a product (each column's sums as
    # in one product of all four: the sparse kernel adds each column on its own), not
    # four: the four floats a choice and a state were the analysis's peak on QVBS
    # wlan_dl.  The entries into removed states are dropped there, unless end
    # components are collapsed: then made explicit zeros in column 0, summed with their
    # row's duplicates and dropped as before (the duplicates' order of addition).
    removed = state_map < 0
    targets = [goal] if same else [goal, extra]
    losing = [p & removed for p in prob0[1 if same else 0:]]
    groups = [targets, sure_state, losing] if sure_state.any() else [targets, losing]
    got = quotient_rows(m, kept, state_map, n_red, groups, index, drop=not mecs.n_mecs,
                        positive=(len(groups) - 1,))
    del removed, targets, losing, groups
    one_step = got.sums[0]
    to_goal = np.ascontiguousarray(one_step[:, 0])
    to_extra = None if same else np.ascontiguousarray(one_step[:, 1])
    if sure_state.any():  # a move into a value-1 state joins the goal's (_without_one's sum)
        to_goal = to_goal + got.sums[1]
    one_step = got.sums[-1]  # whether each choice may move to a losing removed state
    leaks = [np.ascontiguousarray(one_step[:, j]) for j in range(one_step.shape[1])]
    if same:  # the one model's, as both
        leaks = [leaks[0], leaks[0]]
    matrix = sp.csr_array((got.data, got.indices, got.indptr), shape=(kept.size, n_red))
    del one_step, got
    if mecs.n_mecs:
        matrix.sum_duplicates()
        matrix.eliminate_zeros()
        compact(matrix)

    # with collapsed end components, a maximum's value-1 states out of the quotient
    # (_without_one): Prob1E (a collapsed end component leaves whole)
    sure = np.zeros(n_red, dtype=bool)
    if without_one and sense is Sense.MAX and mecs.n_mecs and not sure_state.any():
        zero0 = np.zeros(n_red, dtype=bool)
        zero0[state_map[maybe & prob0[j0]]] = True
        sure, spared = _one(sense, matrix, row_groups, zero0, leaks[j0])
        sure &= ~zero0
        del zero0
        if spared is not None and sure.any():  # the lift's strategy there (the docs)
            played = attractor_strategy(mdp, sure, spared, row_groups, kept, state_map,
                                         n_plain, mecs)
            if played is not None:
                shared[ATTRACTOR_STRATEGY] = played
        del spared
    if sure.any():
        cut = _without_one(matrix, row_groups, sure, [to_goal, to_extra], leaks)
        matrix, row_groups, kept = cut.matrix, cut.row_groups, kept[cut.choices]
        to_goal, to_extra, leaks = cut.to_goal, cut.to_extra, cut.leaks
        sure_state[maybe] = sure[state_map[maybe]]
        maybe = maybe & ~sure_state
        if mecs.n_mecs:
            mecs = _fewer_components(mecs, cut.new_id, sure, n_plain, mdp)
        n_plain = int(np.count_nonzero(~sure[:n_plain]))
        state_map = np.where(state_map >= 0, cut.new_id[np.maximum(state_map, 0)], -1
                             ).astype(state_map.dtype, copy=False)
        n_red = int(cut.row_groups.shape[0] - 1)
        del cut
    del sure

    order, comp_level = quotient_blocks(found, matrix, row_groups, maybe, sure_state, state_map,
                                        lambda: state_levels(m, mdp.row_groups), crowd)
    # kept by the models for the certificate: in the index type (4 bytes a state and a
    # component where the size allows; the same numbers)
    layers = (read_only(found.component.astype(index_dtype(n), copy=False)),
              read_only(comp_level.astype(index_dtype(n), copy=False)))
    # their int64 originals freed before the quotients' masks are made (QVBS csma 4-2:
    # 8.8 bytes a transition at the analysis's traced peak, its end)
    del found, comp_level, crowd
    init = int(mdp.initial)

    def quotient(target: np.ndarray, to_target: np.ndarray, j: int) -> Quotient:
        zero = np.zeros(n_red, dtype=bool)
        zero[state_map[maybe & prob0[j]]] = True
        one = target | sure_state
        # the goal's own value-1 states left the quotient, and none is left: the states
        # that remain reach a losing state or choice (a minimum) or cannot avoid one (a
        # maximum) through states that remain, so _one would find none; the wider
        # target's, from other seeds, are searched
        one[maybe] = False if without_one and j == j0 else _one(
            sense, matrix, row_groups, zero, leaks[j])[0][state_map[maybe]]
        unreachable = ~reach[:, j] & ~target
        decided = Qualitative(sense, read_only(prob0[j]), read_only(one),
                              read_only(prob0[j] if sense is Sense.MAX else unreachable))
        initial_value = 1.0 if one[init] else (0.0 if prob0[j][init] else float("nan"))
        return Quotient(
            target=read_only(target.copy()), prob0=read_only(prob0[j]),
            state_map=read_only(state_map), mecs=mecs, n_plain=n_plain, matrix=matrix,
            to_target=read_only(to_target), row_groups=read_only(row_groups),
            choice_origin=read_only(kept), initial=int(state_map[init]),
            initial_value=initial_value if state_map[init] < 0 else float("nan"),
            order=order, zero=read_only(zero), layers=layers, sense=sense,
            qualitative=decided, shared=shared)

    if to_extra is None:
        one = quotient(goal, to_goal, 1)
        return one, one
    return quotient(goal, to_goal, 0), quotient(wide, to_goal + to_extra, 1)

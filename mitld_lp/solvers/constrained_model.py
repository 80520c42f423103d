"""The model a constrained synthesis solves: the product of the world with the joint
automaton (task and constraints), its terminal states merged, and what each choice is
worth for each quantity.

* **Merging** (:func:`merge`): product states whose joint automaton state is terminal
  (every component decided) become one absorbing state per verdict tuple; states only
  reachable through them are dropped.  The ``truncated`` state stays.
* **Decided task** (:attr:`Merged.undecided`): a state is *undecided* when its task
  component has neither accepted nor rejected and some policy still reaches task
  acceptance or truncation from it (graph reachability); expected steps and costs
  count the actions taken in undecided states only.  For a minimum (the component is
  the complement of the posed task) the acceptance is the posed task's: the
  complement's rejection.
* **End components**: a run may stay for ever in an end component of the
  non-absorbing states; it then decides nothing more (a component that accepts or
  rejects leaves the component's automaton state, which an end component cannot do),
  so every component undecided there counts as not satisfied.  The LP gives each state
  of an end component a *stay* column worth that verdict; in an undecided state a stay
  costs infinitely many steps, so stays there are closed when steps or costs are
  bounded or minimised.  No end component is collapsed: collapsing would lose the steps
  spent in it.
* **Keeping a safety part** (:attr:`Merged.keep`): a task with a safety part (its
  automaton has :data:`~mitld_lp.automata.dta.SAFE` states) is satisfied by a run that
  stays for ever in states where the task's automaton state is persistent.  Each state of
  a maximal end component of the non-absorbing states whose task component is
  persistent gets one more choice, *keep*: into an absorbing state whose verdict is the
  task accepted and the constraints as they are (a co-safe constraint cannot change
  inside an end component: an accepted component never becomes undecided again).  A
  policy that takes it then plays the component's internal choices for ever (the
  controller does so), which satisfies the task; the task is then *decided* (expected
  steps and costs stop counting).  With the plain stays above (worth the verdicts, the
  task not satisfied) these are every outcome an end component can give, so the LP over
  both is the multi-objective construction of Etessami, Kwiatkowska, Vardi and
  Yannakakis (2008) for one safety (obligation) objective and co-safe constraints.
* **Exact evaluation** (:func:`evaluate`): the values of a randomised policy (a
  distribution over choices and a stay probability per state) from one sparse solve on
  its Markov chain.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.automata.joint import ACCEPTED, REJECTED, UNDECIDED, Joint
from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.product import Absorbing, ProductState
from mitld_lp.solvers.quotient import backward_reachable, maximal_end_components
from mitld_lp.util.traversal import breadth_first_order, strong_components

__all__ = ["Merged", "merge", "Quantity", "columns", "evaluate", "Evaluation", "trapped_bottoms"]


@dataclass(frozen=True, slots=True, eq=False)
class Merged:
    """The merged model.

    Attributes:
        mdp: the merged MDP (absorbing states: one per verdict tuple, and truncated).
        origin: per merged state, its product state index (-1 for a verdict state).
        of_product: per product state, its merged state (-1: merged away or dropped).
        joint_state: per merged state, its joint automaton state (-1 if absorbing).
        verdicts: per merged state, the components' verdicts (a verdict state's tuple;
            for a non-absorbing state its joint state's; for truncated all undecided).
        absorbing, truncated, undecided: bool masks over merged states.
        stay_ok: per merged state, whether it lies in an end component of the
            non-absorbing states (a run may stay there for ever).
        internal: per merged choice, whether it keeps the run in its end component.
        keep: per merged choice, whether it is a *keep* choice (module docs).
        keep_internal: per merged choice, whether it keeps the run in its end
            component of persistent task states (what a kept run plays).
        state_map: per product state, its merged state (a verdict state for a merged
            terminal one; -1: not reachable in the merged model).
        choice_origin: per merged choice, the product choice it is (-1: an absorbing
            state's self-loop or a *keep* choice).
        share: per merged state, the share of a step taken there that expected steps
            and costs count (None: 1 in the ``undecided`` states, 0 elsewhere); an
            information state's is the posterior weight of its hypotheses whose task
            is undecided (:mod:`mitld_lp.routes.sensed_constrained`).
        stay_values: per merged state and component, what staying there for ever is
            worth (None: its verdict, 1 accepted, else 0); an information state's is the
            posterior weight of its hypotheses that accepted the component.
    """

    mdp: MDP
    origin: np.ndarray
    of_product: np.ndarray
    joint_state: np.ndarray
    verdicts: np.ndarray
    absorbing: np.ndarray
    truncated: np.ndarray
    undecided: np.ndarray
    stay_ok: np.ndarray
    internal: np.ndarray
    keep: np.ndarray
    keep_internal: np.ndarray
    state_map: np.ndarray
    choice_origin: np.ndarray
    share: np.ndarray | None = None
    stay_values: np.ndarray | None = None


def merge(mdp: MDP, joint: Joint, *, negated: bool = False) -> Merged:
    """:class:`Merged` of the product ``mdp`` of a world with ``joint.dta``.

    ``negated``: the joint's first component is the complement of the posed task (a
    minimum, solved as the complement's maximum).  Steps and costs still count while the
    *posed* task is undecided: neither of them has a verdict and some policy could still
    make the posed task accept, that is, make the complement reject (or reach truncation).
    Counted against the complement instead, a state from which every policy satisfies
    the posed task would not be charged on its way there."""
    n = mdp.n_states
    k = len(joint.parts)
    jstate = np.full(n, -1, dtype=np.int64)
    trunc = np.zeros(n, dtype=bool)
    for i, rec in enumerate(mdp.states):
        if isinstance(rec, ProductState):
            jstate[i] = rec.automaton
        elif rec is Absorbing.TRUNCATED:
            trunc[i] = True
        else:  # the joint automaton has no accepting or rejecting state
            raise ValueError(f"unexpected absorbing state {rec!r} in a joint product")
    term_j = np.array([joint.terminal(j) for j in range(joint.dta.n_states)], dtype=bool)
    terminal = (jstate >= 0) & term_j[np.maximum(jstate, 0)]
    vtab = np.array(joint.verdicts, dtype=np.int64).reshape(-1, k)
    # verdict states: one per distinct verdict tuple among terminal states
    tuples = vtab[jstate[terminal]] if terminal.any() else np.zeros((0, k), dtype=np.int64)
    uniq, which = np.unique(tuples, axis=0, return_inverse=True)
    keep = ~terminal
    n_keep = int(keep.sum())
    to_new = np.full(n, -1, dtype=np.int64)
    to_new[keep] = np.arange(n_keep)
    to_new[terminal] = n_keep + which.reshape(-1)
    n_new = n_keep + uniq.shape[0]
    # rows of the kept non-absorbing states, columns remapped
    cstate = mdp.choice_state()
    active = keep & ~trunc
    rows = np.flatnonzero(active[cstate])
    sub = mdp.matrix[rows]
    sub = sp.csr_array((sub.data, to_new[sub.indices], sub.indptr), shape=(rows.size, n_new))
    sub.sum_duplicates()
    # forward reachability from the initial state
    start = int(to_new[mdp.initial])
    owner = to_new[cstate[rows]]
    coo = sub.tocoo()
    graph = sp.csr_array((np.ones(coo.nnz), (owner[coo.row], coo.col)), shape=(n_new, n_new))
    order = breadth_first_order(graph, start)
    reach = np.zeros(n_new, dtype=bool)
    reach[np.asarray(order)] = True
    # renumber the reachable merged states
    final = np.full(n_new, -1, dtype=np.int64)
    final[reach] = np.arange(int(reach.sum()))
    m = int(reach.sum())
    origin_all = np.full(n_new, -1, dtype=np.int64)
    origin_all[to_new[keep]] = np.flatnonzero(keep)
    origin = origin_all[reach]
    is_abs_all = np.zeros(n_new, dtype=bool)
    is_abs_all[n_keep:] = True
    is_abs_all[to_new[trunc]] = True
    absorbing = is_abs_all[reach]
    truncated = np.zeros(m, dtype=bool)
    truncated[final[to_new[trunc]][final[to_new[trunc]] >= 0]] = True
    js = np.full(m, -1, dtype=np.int64)
    ordinary = (origin >= 0) & ~truncated
    js[ordinary] = jstate[origin[ordinary]]
    verdicts = np.full((m, k), UNDECIDED, dtype=np.int64)
    verdicts[ordinary] = vtab[js[ordinary]]
    verdict_states = np.flatnonzero(reach[n_keep:]) + n_keep
    verdicts[final[verdict_states]] = uniq[verdict_states - n_keep]
    # assemble the merged MDP: kept rows of reachable states, self-loops for absorbing
    row_keep = reach[owner]
    sub = sub[np.flatnonzero(row_keep)]
    sub = sp.csr_array((sub.data, final[sub.indices], sub.indptr), shape=(sub.shape[0], m))
    row_owner = final[owner[row_keep]]
    per_state = np.bincount(row_owner, minlength=m)
    per_state[absorbing] = 1
    row_groups = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(per_state, out=row_groups[1:])
    n_choices = int(row_groups[-1])
    # the kept rows come ordered by owner (the product numbers choices state by state)
    rank = np.arange(row_owner.size) - np.searchsorted(row_owner, row_owner, side="left")
    target_row = row_groups[row_owner] + rank
    abs_rows = row_groups[:-1][absorbing]
    coo = sub.tocoo()
    r = np.concatenate([target_row[coo.row], abs_rows])
    c = np.concatenate([coo.col, np.flatnonzero(absorbing)])
    v = np.concatenate([coo.data, np.ones(int(absorbing.sum()))])
    matrix = sp.csr_array((v, (r, c)), shape=(n_choices, m))
    actions = np.full(n_choices, ABSORB, dtype=np.int32)
    src_rows = rows[row_keep]
    actions[target_row] = mdp.choice_actions[src_rows]
    choice_origin = np.full(n_choices, -1, dtype=np.int64)
    choice_origin[target_row] = src_rows
    state_map = np.where(to_new >= 0, final[np.maximum(to_new, 0)], -1)
    task_acc = verdicts[:, 0] == ACCEPTED
    new = MDP(
        matrix=matrix,
        row_groups=row_groups,
        choice_actions=actions,
        action_names=mdp.action_names,
        initial=int(final[start]),
        target=absorbing & task_acc,
        sink=absorbing & ~task_acc & ~truncated,
        truncated=truncated,
        states=tuple(range(m)),
    )
    of_product = np.full(n, -1, dtype=np.int64)
    of_product[keep] = final[to_new[keep]]
    task_dta = joint.parts[0]
    persistent = np.zeros(task_dta.n_states + 1, dtype=bool)  # index -1: not ordinary
    persistent[[q for q in range(task_dta.n_states) if task_dta.is_safe(q)]] = True
    comp = np.array([c[0] for c in joint.components] + [-1], dtype=np.int64)
    kept = _keeping(new, ~absorbing & persistent[comp[js]])
    if kept is not None:
        new, verdicts, absorbing, truncated, origin, js, keep_choice, keep_internal, pos = (
            _with_keeps(new, verdicts, absorbing, truncated, origin, js, *kept))
        moved = np.full(new.n_choices, -1, dtype=np.int64)
        moved[pos] = choice_origin
        choice_origin = moved
        m = new.n_states
        task_acc = verdicts[:, 0] == ACCEPTED
    else:
        keep_choice = keep_internal = np.zeros(new.n_choices, dtype=bool)
    # undecided: task open and the posed task's acceptance (or truncation) still reachable
    e = new.matrix.tocoo()
    cs = new.choice_state()
    seeds = ((verdicts[:, 0] == REJECTED) if negated else task_acc) | truncated
    can = backward_reachable(m, cs[e.row], e.col, seeds)
    undecided = ~absorbing & (verdicts[:, 0] == UNDECIDED) & can
    mecs = maximal_end_components(new, ~absorbing)
    stay_ok = mecs.mec_of >= 0
    return Merged(new, origin, of_product, js, verdicts, absorbing, truncated, undecided,
                  stay_ok, np.asarray(mecs.internal), keep_choice, keep_internal, state_map,
                  choice_origin)


def _keeping(mdp: MDP, persistent: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The states of the maximal end components of ``persistent`` states and their
    internal choices (None when there is none)."""
    if not persistent.any():
        return None
    mecs = maximal_end_components(mdp, persistent)
    inside = mecs.mec_of >= 0
    return (inside, np.asarray(mecs.internal)) if inside.any() else None


def _with_keeps(mdp: MDP, verdicts: np.ndarray, absorbing: np.ndarray,
                truncated: np.ndarray, origin: np.ndarray, js: np.ndarray,
                inside: np.ndarray, internal: np.ndarray) -> tuple[Any, ...]:
    """``mdp`` with a *keep* choice appended to each state of ``inside`` (module docs),
    into one new absorbing state per kept verdict tuple (the task accepted)."""
    m, rg = mdp.n_states, np.asarray(mdp.row_groups, dtype=np.int64)
    kept_states = np.flatnonzero(inside)
    tuples = verdicts[kept_states].copy()
    tuples[:, 0] = ACCEPTED
    uniq, which = np.unique(tuples, axis=0, return_inverse=True)
    u = uniq.shape[0]
    counts = np.diff(rg)
    new_counts = np.concatenate([counts + inside, np.ones(u, dtype=np.int64)])
    new_rg = np.zeros(m + u + 1, dtype=np.int64)
    np.cumsum(new_counts, out=new_rg[1:])
    owner = mdp.choice_state()
    old_pos = new_rg[owner] + (np.arange(owner.size) - rg[owner])
    keep_pos = new_rg[kept_states] + counts[kept_states]
    abs_pos = new_rg[m:m + u]
    coo = mdp.matrix.tocoo()
    rows = np.concatenate([old_pos[coo.row], keep_pos, abs_pos])
    cols = np.concatenate([coo.col, m + which.reshape(-1), m + np.arange(u)])
    vals = np.concatenate([coo.data, np.ones(kept_states.size + u)])
    n_choices = int(new_rg[-1])
    matrix = sp.csr_array((vals, (rows, cols)), shape=(n_choices, m + u))
    actions = np.full(n_choices, ABSORB, dtype=np.int32)
    actions[old_pos] = mdp.choice_actions
    keep_choice = np.zeros(n_choices, dtype=bool)
    keep_choice[keep_pos] = True
    keep_internal = np.zeros(n_choices, dtype=bool)
    keep_internal[old_pos] = internal
    grow = np.zeros(u, dtype=bool)
    absorbing2 = np.concatenate([absorbing, ~grow])
    truncated2 = np.concatenate([truncated, grow])
    verdicts2 = np.concatenate([verdicts, uniq.reshape(u, -1)])
    task_acc = verdicts2[:, 0] == ACCEPTED
    new = MDP(matrix=matrix, row_groups=new_rg, choice_actions=actions,
              action_names=mdp.action_names, initial=mdp.initial,
              target=absorbing2 & task_acc, sink=absorbing2 & ~task_acc & ~truncated2,
              truncated=truncated2, states=tuple(range(m + u)))
    minus = np.full(u, -1, dtype=np.int64)
    return (new, verdicts2, absorbing2, truncated2, np.concatenate([origin, minus]),
            np.concatenate([js, minus]), keep_choice, keep_internal, old_pos)


@dataclass(frozen=True, slots=True)
class Quantity:
    """A quantity of a run: ``kind`` ``"prob"`` (component ``component`` accepted; for
    ``component == 0`` the task), ``"steps"`` or ``"cost"``; ``truncated`` is what the
    truncated state counts as for a probability (1.0 satisfied, 0.0 not)."""

    kind: str
    component: int = 0
    truncated: float = 0.0


def columns(
    merged: Merged, q: Quantity, costs: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """What each LP column is worth for ``q``: per merged choice (the expected value
    collected by taking it: for a probability, the chance to step into an absorbing state
    that satisfies it; for steps 1 and for cost the action's cost, in undecided states)
    and per merged state (a stay: the verdict of staying for ever; 0 for steps and
    costs, whose stays in undecided states are closed)."""
    mdp = merged.mdp
    if q.kind == "prob":
        sat = (merged.verdicts[:, q.component] == ACCEPTED).astype(np.float64)
        absorbed = np.where(merged.absorbing, sat, 0.0)
        absorbed[merged.truncated] = q.truncated
        per_choice = mdp.matrix @ absorbed
        per_choice[np.repeat(merged.absorbing, np.diff(mdp.row_groups))] = 0.0
        if merged.stay_values is not None:
            sat = merged.stay_values[:, q.component]
        return per_choice, np.where(merged.absorbing, 0.0, sat)
    cs = mdp.choice_state()
    charged = (merged.undecided[cs] & ~merged.keep).astype(np.float64)
    if merged.share is not None:
        charged *= merged.share[cs]
    if q.kind == "cost":
        assert costs is not None
        acts = mdp.choice_actions
        charged = charged * np.where(acts >= 0, costs[np.maximum(acts, 0)], 0.0)
    return charged, np.zeros(mdp.n_states)


@dataclass(frozen=True, slots=True)
class Evaluation:
    """The exact values of a randomised policy, per quantity asked, and the expected
    visits of each state (``inf`` steps when the run may stay undecided for ever)."""

    values: tuple[float, ...]
    visits: np.ndarray


def trapped_bottoms(chain: sp.csr_array, live: np.ndarray, exits: np.ndarray) -> np.ndarray:
    """The bottom strongly connected sets of the ``live`` states of a Markov chain
    (``chain``, state by state) that cannot reach ``exits``: where a run that can no
    longer leave stays for ever."""
    m = chain.shape[0]
    coo = chain.tocoo()
    pos = coo.data > 0
    trapped = live & ~backward_reachable(m, coo.row[pos], coo.col[pos], exits)
    bottom = np.zeros(m, dtype=bool)
    if trapped.any():
        idx = np.flatnonzero(trapped)
        inner = chain[idx][:, idx]
        n_c, lab = strong_components(inner)
        ic = inner.tocoo()
        leaves = np.zeros(n_c, dtype=bool)
        cross = (lab[ic.row] != lab[ic.col]) & (ic.data > 0)
        leaves[lab[ic.row[cross]]] = True
        bottom[idx[~leaves[lab]]] = True
    return bottom


def evaluate(
    merged: Merged,
    prob: np.ndarray,
    stay: np.ndarray,
    quantities: list[tuple[np.ndarray, np.ndarray, bool]],
) -> Evaluation:
    """The value of each quantity ``(per_choice, per_stay, counts_steps)`` under the
    policy taking choice ``c`` with probability ``prob[c]`` and staying in state ``s``
    for ever with probability ``stay[s]``: ``sum_s y_s r_s`` with ``y`` the expected
    visits (one sparse solve ``(I - Q)' y = e_init`` over the transient states) and
    ``r_s`` the value collected per visit.  States the policy can never leave (a closed
    set of the chain) count as stays; a quantity that counts steps is ``inf`` when an
    undecided state is stayed in with positive probability."""
    mdp = merged.mdp
    m = mdp.n_states
    cs = mdp.choice_state()
    live = ~merged.absorbing
    weighted = sp.diags_array(prob) @ mdp.matrix
    owner = sp.csr_array((np.ones(cs.size), (cs, np.arange(cs.size))), shape=(m, cs.size))
    chain = sp.csr_array(owner @ weighted)
    # the bottom sets of the trapped part act as stays; the rest of it is transient
    bottom = trapped_bottoms(chain, live, (stay > 0) | merged.absorbing)
    transient = live & ~bottom
    t_idx = np.flatnonzero(transient)
    visits = np.zeros(m)
    entry = np.zeros(m)  # probability of first entering each bottom state
    if transient[mdp.initial]:
        qtt = chain[t_idx][:, t_idx]
        rhs = np.zeros(t_idx.size)
        rhs[np.searchsorted(t_idx, mdp.initial)] = 1.0
        import scipy.sparse.linalg as spla

        y = spla.spsolve((sp.eye_array(t_idx.size, format="csc") - qtt.T).tocsc(), rhs)
        visits[t_idx] = np.atleast_1d(np.asarray(y, dtype=np.float64))
        b_idx = np.flatnonzero(bottom)
        if b_idx.size:
            entry[b_idx] = chain[t_idx][:, b_idx].T @ visits[t_idx]
    elif bottom[mdp.initial]:
        entry[mdp.initial] = 1.0
    out = []
    for per_choice, per_stay, counts_steps in quantities:
        r = owner @ (prob * per_choice) + stay * per_stay
        value = float(visits[transient] @ r[transient])
        if counts_steps:
            stuck = (visits * stay)[merged.undecided].sum() + entry[merged.undecided].sum()
            value = float("inf") if stuck > 1e-12 else value
        else:
            # a bottom state is stayed in for ever: its verdict is its stay value
            value += float(entry[bottom] @ per_stay[bottom])
        out.append(value)
    return Evaluation(tuple(out), visits)

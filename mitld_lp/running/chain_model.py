"""A controlled chain as data (:class:`Chain`) and what every chain builder shares: the
chains' own labels, a world proposition's label, the matrix from rows.  The builders
(:mod:`mitld_lp.running.chain` for a deterministic or randomised controller,
:mod:`mitld_lp.running.sensed_chain` for one acting on sensor reports,
:mod:`mitld_lp.running.band_chain` for a band's interval chain) stand above it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

__all__ = ["Chain", "CHAIN_LABELS", "prop_labels", "rows_matrix"]

CHAIN_LABELS = ("init", "accept", "reject", "truncated", "staying", "keeping", "beyond",
                "persistent")
"""The chains' own labels (``beyond``: a sensed controller's memory past its model,
:mod:`mitld_lp.running.sensed_chain`)."""


@dataclass(frozen=True, slots=True, eq=False)
class Chain:
    """A finite Markov chain: state 0 is the initial one.

    ``matrix``: ``(n, n)`` CSR transition probabilities; ``labels[i]``: the labels of
    state ``i`` (without ``init``); ``valuations[i]``: its valuation text;
    ``origin[i]``: its product state (-1 for the chain's own absorbing states),
    ``staying[i]`` whether a randomised controller has drawn *stay* there and
    ``keeping[i]`` whether it has drawn *keep* (the task's safety part kept for ever);
    ``rewards``: reward models, each ``(name, per state the reward earned there)``."""

    matrix: sp.csr_array
    labels: tuple[frozenset[str], ...]
    valuations: tuple[str, ...]
    origin: np.ndarray
    staying: np.ndarray
    keeping: np.ndarray
    rewards: tuple[tuple[str, np.ndarray], ...] = ()

    @property
    def n_states(self) -> int:
        return self.matrix.shape[0]

    def accepting(self) -> np.ndarray:
        return np.array(["accept" in x for x in self.labels], dtype=bool)


def rows_matrix(rows: list[dict[int, float]]) -> sp.csr_array:
    """A chain's ``(n, n)`` CSR matrix from its rows (``rows[i]``: successor to
    probability), each row's successors in increasing order."""
    n = len(rows)
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum([len(r) for r in rows], out=indptr[1:])
    cols = np.fromiter((c for r in rows for c in sorted(r)), dtype=np.int64,
                       count=int(indptr[-1]))
    vals = np.fromiter((r[c] for r in rows for c in sorted(r)), dtype=np.float64,
                       count=int(indptr[-1]))
    return sp.csr_array((vals, cols, indptr), shape=(n, n))


def prop_labels() -> Callable[[str], str]:
    """A world proposition's label in a chain: its name, or ``world_<name>`` for one named
    like a chain's own label."""
    reserved = set(CHAIN_LABELS) | {"target", "sink"}
    return lambda p: f"world_{p}" if p in reserved else p

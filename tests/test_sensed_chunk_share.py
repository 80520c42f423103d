"""The sensed build's chunks bounded by a share of the hypotheses found so far
(:func:`mitld_lp.sensing.chunks.chunk_bound`): a build whose chunks are so bounded and
one whose chunks are bounded by :data:`~mitld_lp.sensing.chunks.CHUNK_HYPOTHESES` alone
give the same information states, posteriors, rows and moves (compared as sets, each
state by its key), numbered alike; the bound itself checked by hand."""

from __future__ import annotations

import pytest
from test_sensing_build import CASES, canonical

from mitld_lp.automata.translate import to_dta
from mitld_lp.sensing import chunks, frontier
from mitld_lp.sensing.belief import belief_product


def _build(monkeypatch: pytest.MonkeyPatch, case: str, share: int, least: int
           ) -> tuple[dict, int]:
    """The case built with chunks bounded by ``share`` and ``least``, in canonical form,
    and the number of chunks it expanded."""
    monkeypatch.setattr(chunks, "CHUNK_SHARE", share)
    monkeypatch.setattr(chunks, "CHUNK_LEAST", least)
    calls = [0]
    expand = frontier.FrontierBuilder.expand

    def counted(self, a, b):
        calls[0] += 1
        return expand(self, a, b)

    monkeypatch.setattr(frontier.FrontierBuilder, "expand", counted)
    model = CASES[case]()
    belief = belief_product(model.game, to_dta(model.spec), model.distributions,
                            dict(model.sensors), model.epsilon, max_states=10**6)
    return canonical(belief), calls[0]


@pytest.mark.parametrize("case", ["one camera", "two cameras", "a safety part"])
def test_capped_and_uncapped_builds_are_the_same(monkeypatch, case: str) -> None:
    # uncapped: the share's bound never below CHUNK_HYPOTHESES; capped: a chunk at most
    # a sixteenth of the hypotheses found so far, down to a single hypothesis (39-48
    # chunks here against 9-12)
    whole, few = _build(monkeypatch, case, 1, chunks.CHUNK_HYPOTHESES)
    capped, many = _build(monkeypatch, case, 16, 1)
    assert many > 2 * few  # the share bound split the levels
    assert set(capped["order"]) == set(whole["order"])
    assert capped["weights"] == whole["weights"]
    rows = {k: frozenset(v.items()) for k, v in capped["rows"].items()}
    assert rows == {k: frozenset(v.items()) for k, v in whole["rows"].items()}
    assert capped["moves"] == whole["moves"]
    assert capped["initial"] == whole["initial"]
    assert capped["order"] == whole["order"]  # numbered alike: the solvers' ties too


def test_chunk_bound_by_hand(monkeypatch) -> None:
    monkeypatch.setattr(chunks, "CHUNK_HYPOTHESES", 8192)
    monkeypatch.setattr(chunks, "CHUNK_SHARE", 256)
    monkeypatch.setattr(chunks, "CHUNK_LEAST", 2048)
    # 1,000 found: 3 by the share, raised to 2,048; 1,000,000: 3,906; 10**7: 39,062,
    # cut to 8,192
    assert [chunks.chunk_bound(n) for n in (0, 1000, 10**6, 10**7)] == [
        2048, 2048, 3906, 8192]
    # states holding 1,000 hypotheses each: two fit under 2,048 (10**5 found), three
    # under 3,906 (10**6 found)
    held = __import__("numpy").full(10, 1000)
    assert chunks.chunk_end(held, 5, 10**5) == 7
    assert chunks.chunk_end(held, 5, 10**6) == 8

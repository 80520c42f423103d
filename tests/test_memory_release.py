"""The product's memory: what the build lets go of before the matrix is assembled, and
the narrower arrays it keeps, each answering what the wider ones did.

* the layers' per-row and per-slot arrays (the world's rows, the actions' starts and
  counts, the labels) are freed before ``_assemble`` runs, and the layers themselves as
  soon as ``product`` returns, by reference counting alone (the cyclic collector off):
  weak references to them are dead;
* the states' codes are int32 when every one fits, int64 otherwise, and the records and
  positions read from int32 codes are those read from the int64 ones;
* ``MDPShape.choice_state`` (counted up from the row groups) against ``np.repeat`` over
  the row groups' differences, with states that have no choice.
"""

from __future__ import annotations

import gc
import importlib
import weakref

import numpy as np
import pytest

from mitld_lp.automata.sta import make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.distributions import geometric
from mitld_lp.logic import parse
from mitld_lp.mdp import MDPShape
from mitld_lp.product import ProductState, product
from mitld_lp.product.states import KeyCodec, ProductStates
from mitld_lp.util.arrays import narrow_copy
from mitld_lp.worlds.grid import GridWorld

build = importlib.import_module("mitld_lp.product.build")
SPEC = "D[mu] b & F(b & F[0,3] goal)"
ROWS = ("row_succ", "row_prob", "row_start", "row_len", "act_count", "act_start", "props")


def _world_and_sta():
    game = GridWorld.make(3, 3, start=(0, 0), slip=0.1, regions={"goal": [(2, 2)]})
    return game, make_sta(to_dta(parse(SPEC)), {"b": geometric(0.4)}, 0.01)


@pytest.fixture
def no_gc():
    was = gc.isenabled()
    gc.collect()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def test_world_rows_and_layers_freed_before_assembly(monkeypatch, no_gc) -> None:
    seen: dict[str, object] = {}

    class Watched(build.Layers):
        def check_rows(self) -> None:  # the last call before the build lets go of them
            super().check_rows()
            seen["layers"] = weakref.ref(self)
            seen["arrays"] = {n: weakref.ref(getattr(self, n).data) for n in ROWS}

    inner = build._assemble

    def assemble(f, *args):
        alive = [n for n, ref in seen["arrays"].items() if ref() is not None]
        seen["alive_at_assembly"] = alive
        return inner(f, *args)

    monkeypatch.setattr(build, "Layers", Watched)
    monkeypatch.setattr(build, "_assemble", assemble)
    game, sta = _world_and_sta()
    mdp = product(game, sta)
    assert mdp.n_states > 10
    assert seen["alive_at_assembly"] == []  # every row array went before the assembly
    assert seen["layers"]() is None  # and the layers when product returned, gc off


def test_grid_product_codes_are_int32_and_read_as_int64_ones() -> None:
    game, sta = _world_and_sta()
    mdp = product(game, sta)
    states = mdp.states
    assert isinstance(states, ProductStates)
    keys = states._keys
    assert keys.dtype == np.int32
    wide = ProductStates(keys.astype(np.int64), states._games, states._situations,
                         states._codec)
    assert list(wide) == list(states)
    for i, record in enumerate(wide):
        assert states.position(record) == i == wide.position(record)


def test_narrow_copy_keeps_int64_where_a_value_does_not_fit() -> None:
    small = np.array([-3, 0, 2**31 - 1], dtype=np.int64)
    out = narrow_copy(small)
    assert out.dtype == np.int32 and out.tolist() == small.tolist()
    assert not np.shares_memory(out, small)
    for big in (np.array([0, 2**31], dtype=np.int64), np.array([-(2**31) - 1, 5])):
        kept = narrow_copy(big)
        assert kept.dtype == np.int64 and kept.tolist() == big.tolist()
        assert not np.shares_memory(kept, big)
    assert narrow_copy(np.zeros(0, dtype=np.int64)).size == 0


def test_a_code_past_int32_is_no_state_of_int32_codes() -> None:
    # key(g, q, sid) = (g * 1 + q) * 2**32 + sid: g = 1 wraps to 1 in 32 bits
    codec = KeyCodec(1, 2**32)
    games = ["a", "b"]
    sits = [(frozenset(), 0), (frozenset(), 1)]
    states = ProductStates(np.array([0, 1], dtype=np.int32), games, sits, codec)
    assert states.position(ProductState("a", 0, frozenset(), 1)) == 1  # key 1
    assert states.position(ProductState("b", 0, frozenset(), 1)) is None  # 2**32 + 1


class _Shape(MDPShape):
    __slots__ = ("row_groups",)

    def __init__(self, row_groups: np.ndarray) -> None:
        self.row_groups = row_groups


@pytest.mark.parametrize("dtype", [np.int64, np.int32])
def test_choice_state_against_repeat(dtype) -> None:
    rng = np.random.default_rng(3)
    for _ in range(300):
        n = int(rng.integers(0, 9))
        counts = rng.integers(0, 4, n)  # states without a choice too
        groups = np.concatenate([[0], np.cumsum(counts)]).astype(dtype)
        got = _Shape(groups).choice_state()
        assert got.dtype == np.int64
        assert got.tolist() == [s for s, k in enumerate(counts.tolist()) for _ in range(k)]

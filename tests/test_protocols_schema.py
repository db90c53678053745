"""A field declared once in a message dataclass flows through every path derived from the schema:
construction, the general encoder and decoder, the checks (read_body, accept_body) and the fast path;
a typed field carried inside another (the exploration schedule) keeps the bytes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import msgpack
import numpy as np
import pytest
from wire_helpers import N_ACTIONS, same, small_transitions

from agents.nnql.config import NNQLConfig
from protocols import fastpath
from protocols.arrays import ext_hook
from protocols.codec import _decode, _encode, _packer, decode, encode
from protocols.errors import ProtocolError
from protocols.limits import Limits
from protocols.messages import KINDS, ExplorationSchedule, TransitionBatch, WeightsUpdate, register
from protocols.schema import column, schema_of, text

LIMITS = Limits(n_actions=N_ACTIONS)


@dataclass(kw_only=True, eq=False)
class WideBatch(TransitionBatch):
    """TransitionBatch with three more columns, as a learner with memory would add."""

    KIND: ClassVar[str] = "test-wide"
    episode_step: np.ndarray = column("<i4")
    hidden: np.ndarray = column("<f4", width="hidden")
    next_hidden: np.ndarray = column("<f4", width="hidden")


@pytest.fixture
def wide():
    """WideBatch registered for the test only, with its fast path."""
    register(WideBatch)
    try:
        yield fastpath._Format(WideBatch)
    finally:
        del KINDS[WideBatch.KIND]


def wide_batch(n: int = 6, dim: int = 5, width: int = 3, **overrides) -> WideBatch:
    base = small_transitions(n=n, dim=dim)
    rng = np.random.default_rng(2)
    fields = {name: getattr(base, name) for name, _ in TransitionBatch.SCHEMA.fields}
    fields.update(
        episode_step=np.arange(n),  # int64 in, int32 on the wire: the constructor converts
        hidden=rng.random((n, width)),
        next_hidden=rng.random((n, width)),
        sender="a",
        seq=3,
    )
    fields.update(overrides)
    return WideBatch(**fields)


def test_the_new_fields_are_in_the_derived_schema(wide) -> None:
    schema = WideBatch.SCHEMA
    assert [name for name, _ in schema.fields][-3:] == ["episode_step", "hidden", "next_hidden"]
    assert schema.widths == {"obs_dim": ("obs", "next_obs"), "hidden": ("hidden", "next_hidden")}
    assert ("hidden", "next_hidden") in schema.pairs and schema.table
    message = wide_batch()
    assert message.episode_step.dtype == np.int32 and message.hidden.dtype == np.float32
    assert list(message.to_body())[-3:] == ["episode_step", "hidden", "next_hidden"]


@pytest.mark.parametrize("n", [0, 1, 6, 33])
def test_fast_and_general_paths_agree_on_the_new_fields(wide, n: int) -> None:
    message = wide_batch(n=n)
    general = _encode(message, fast=False)
    assert wide.encode(message, _packer().pack) == general
    fast = wide.decode(general, LIMITS)
    reference = _decode(general, LIMITS, fast=False)
    assert isinstance(fast, WideBatch) and isinstance(reference, WideBatch)
    assert same(fast, reference) and same(fast, message)
    assert np.array_equal(fast.next_hidden, message.next_hidden)
    body = reference.to_body()
    accepted = WideBatch.accept_body(body, LIMITS)
    assert accepted is not None and accepted.keys() == body.keys()


@pytest.mark.parametrize(
    ("overrides", "reason", "text"),
    [
        ({"hidden": np.full((6, 3), np.nan)}, "nonfinite", "test-wide.hidden holds 18 NaN"),
        (
            {"next_hidden": np.zeros((6, 2))},
            "shape",
            "test-wide: next_hidden (6, 2) differs from hidden (6, 3)",
        ),
        ({"hidden": np.zeros((6, 0)), "next_hidden": np.zeros((6, 0))}, "shape", "hidden has dimension 0"),
        ({"episode_step": np.arange(5)}, "shape", "test-wide: episode_step has 5 rows, expected 6"),
    ],
)
def test_the_new_fields_are_checked(wide, overrides: dict, reason: str, text: str) -> None:
    wire = _encode(wide_batch(**overrides), fast=False)
    assert wide.decode(wire, LIMITS) is None  # the fast path only accepts
    with pytest.raises(ProtocolError) as err:
        _decode(wire, LIMITS, fast=False)
    assert err.value.reason == reason and text in err.value.message
    assert WideBatch.accept_body(_raw_body(wire), LIMITS) is None


def test_the_fast_path_refuses_a_layout_it_cannot_parse() -> None:
    @dataclass(kw_only=True, eq=False)
    class Tagged(TransitionBatch):
        KIND: ClassVar[str] = "test-tagged"
        tag: str = text()  # a text after the columns

    Tagged.SCHEMA = schema_of(Tagged, Tagged.KIND)
    with pytest.raises(TypeError, match="texts and counts first"):
        fastpath._Format(Tagged)


def _raw_body(wire: bytes) -> dict:
    return msgpack.unpackb(wire, ext_hook=ext_hook, raw=False)["b"]


NNQL_SCHEDULE = {
    "exploration": "boltzmann",
    "temperature_start": 0.2,
    "temperature_end": 0.01,
    "temperature_decay_updates": 12_000,
    "epsilon_start": 1.0,
    "epsilon_end": 0.05,
    "epsilon_decay_updates": 10_000,
}
NIRL_SCHEDULE = {
    "exploration": "boltzmann",
    "temperature_start": 0.5,
    "temperature_end": 0.05,
    "temperature_decay_updates": 900,
}


@pytest.mark.parametrize("schedule", [NNQL_SCHEDULE, NIRL_SCHEDULE])
def test_a_typed_exploration_schedule_keeps_the_weights_bytes(schedule: dict) -> None:
    """The schedule rode inside architecture["exploration"]; typed, it writes the same bytes."""
    tensors = {"0.weight": np.ones((4, 3), np.float32), "0.bias": np.zeros(4, np.float32)}
    architecture = {"obs_dim": 3, "n_actions": 4, "hidden_sizes": [], "activation": "relu"}
    old = WeightsUpdate(
        model="nnql", version=7, tensors=tensors, architecture={**architecture, "exploration": schedule}
    )
    typed = WeightsUpdate(
        model="nnql",
        version=7,
        tensors=tensors,
        architecture=architecture,
        exploration=ExplorationSchedule(**schedule),
    )
    assert encode(typed) == encode(old)
    decoded = decode(encode(old))
    assert decoded.exploration == ExplorationSchedule(**schedule)
    assert decoded.architecture == architecture
    assert decode(encode(WeightsUpdate(model="m", version=1, tensors={}))).exploration is None
    assert ExplorationSchedule.of(NNQLConfig()) == ExplorationSchedule(**NNQL_SCHEDULE)


@pytest.mark.parametrize(
    ("schedule", "text"),
    [
        ({"exploration": "softmax"}, "weights.architecture.exploration.exploration = 'softmax'"),
        ({**NIRL_SCHEDULE, "temperature_end": "low"}, "temperature_end must be a number"),
        ({"exploration": "epsilon", "epsilon_start": 1.0}, "epsilon_end must be a number"),
        ({**NIRL_SCHEDULE, "temperature_start": 0.0}, "temperatures must be > 0"),
    ],
)
def test_a_malformed_exploration_schedule_is_rejected(schedule: dict, text: str) -> None:
    wire = encode(WeightsUpdate(model="m", version=1, tensors={}, architecture={"exploration": schedule}))
    with pytest.raises(ProtocolError, match=text):
        decode(wire)

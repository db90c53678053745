"""Fuzzing the decoder: whatever arrives, decoding returns a valid message or raises ProtocolError
with a known reason - never another exception, never a hang."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from wire_helpers import N_ACTIONS, any_message, raw_envelope, small_transitions

from protocols.codec import decode, encode
from protocols.errors import REASONS, ProtocolError
from protocols.limits import Limits
from protocols.messages import DemoBatch, EpisodeMeta, EvalReport, Message, StatusReport, WeightsUpdate

LIMITS = Limits(n_actions=N_ACTIONS, max_message_bytes=1 << 20)
FUZZ = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def outcome(data: bytes) -> str:
    """ "ok" or the ProtocolError reason; any other exception fails the test."""
    try:
        assert isinstance(decode(data, LIMITS), Message)
        return "ok"
    except ProtocolError as exc:
        assert exc.reason in REASONS and exc.message
        return exc.reason


pytestmark = pytest.mark.timeout(120)

# One valid message of every kind: mutating fixed messages keeps the fuzzing cheap (drawing whole
# messages with numpy arrays is what costs time; the round-trip tests already do that).
CORPUS = [
    encode(m)
    for m in (
        small_transitions(n=8),
        DemoBatch(
            source="astar",
            quality="optimal",
            episode_lengths=[2, 1],
            obs=np.ones((5, 11)),
            actions=[0, 1, 2],
            rewards=[0, 0, 1],
            terminations=[False, True, True],
            truncations=[False, False, False],
            episodes=[EpisodeMeta(map_id="m", start=(1, 2), goal=(3, 4), seed=1)] * 2,
        ),
        WeightsUpdate(
            model="nnql",
            version=3,
            tensors={"w": np.ones((4, 3), np.float32), "b": np.zeros(4), "n": np.array(7)},
            architecture={"hidden": [4], "activation": "relu"},
        ),
        EvalReport(model="nnql", policy_version=3, metrics={"unseen": {"success": 0.5, "ci": [0.4, 0.6]}}),
        StatusReport(counters={"rx": 5}, rates={"rx": 1.5}, losses={"td": 0.1}, last_eval={"unseen": 0.5}),
    )
]
corpus = st.sampled_from(CORPUS)


@FUZZ
@given(data=st.binary(max_size=4096))
def test_random_bytes(data: bytes) -> None:
    outcome(data)


@settings(FUZZ, max_examples=40)
@given(message=any_message, cut=st.floats(0, 1, exclude_max=True))
def test_truncated_messages_are_always_rejected(message, cut: float) -> None:
    wire = encode(message)
    assert outcome(wire[: int(cut * len(wire))]) != "ok"


@FUZZ
@given(wire=corpus, cut=st.integers(0, 10**6))
def test_every_prefix_is_rejected(wire: bytes, cut: int) -> None:
    assert outcome(wire[: cut % len(wire)]) != "ok"


@FUZZ
@given(wire=corpus, flips=st.lists(st.integers(0, 2**40), min_size=1, max_size=8))
def test_bit_flips(wire: bytes, flips: list[int]) -> None:
    wire = bytearray(wire)
    for flip in flips:
        bit = flip % (8 * len(wire))
        wire[bit // 8] ^= 1 << (bit % 8)
    outcome(bytes(wire))


@FUZZ
@given(wire=corpus, junk=st.binary(min_size=1, max_size=64))
def test_trailing_bytes_are_rejected(wire: bytes, junk: bytes) -> None:
    assert outcome(wire + junk) == "malformed"


@FUZZ
@given(
    version=st.one_of(
        st.integers(-(2**63), 2**64 - 1).filter(lambda v: v != 1), st.text(max_size=4), st.none(), st.floats()
    )
)
def test_wrong_versions(version) -> None:
    assert outcome(raw_envelope("status", {}, version=version)) == "version"


@FUZZ
@given(value=st.sampled_from([np.nan, np.inf, -np.inf]), row=st.integers(0, 3), col=st.integers(0, 10))
def test_non_finite_observations(value: float, row: int, col: int) -> None:
    obs = np.zeros((4, 11), np.float32)
    obs[row, col] = value
    assert outcome(encode(small_transitions(obs=obs))) == "nonfinite"
    assert outcome(encode(small_transitions(next_obs=obs))) == "nonfinite"


@FUZZ
@given(rows=st.integers(0, 8), dim=st.integers(0, 12))
def test_wrong_shapes(rows: int, dim: int) -> None:
    wire = encode(small_transitions(next_obs=np.zeros((rows, dim))))
    expected = "ok" if (rows, dim) == (4, 11) else "shape"
    assert outcome(wire) == expected


@settings(FUZZ, max_examples=10)
@given(n=st.integers(LIMITS.max_message_bytes // 100, LIMITS.max_message_bytes // 40))
def test_oversize(n: int) -> None:
    assert outcome(encode(small_transitions(n=n))) == "oversize"


@FUZZ
@given(
    obj=st.recursive(
        st.none() | st.integers() | st.text() | st.binary() | st.floats(),
        lambda x: st.lists(x) | st.dictionaries(st.text(), x),
        max_leaves=30,
    )
)
def test_any_msgpack_value(obj) -> None:
    try:
        data = msgpack.packb(obj)
    except (OverflowError, ValueError):  # integers msgpack cannot represent
        return
    assert outcome(data) != "ok"

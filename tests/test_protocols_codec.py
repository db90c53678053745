"""Codec round trips (hypothesis, every message kind) and the checks decoding applies."""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from wire_helpers import (
    N_ACTIONS,
    any_message,
    demo_batches,
    eval_reports,
    learner_statuses,
    raw_envelope,
    same,
    small_transitions,
    transition_batches,
    weights_updates,
)

from protocols.arrays import pack_array, unpack_array
from protocols.codec import decode, encode
from protocols.errors import REASONS, ProtocolError
from protocols.limits import Limits
from protocols.messages import KINDS, DemoBatch, EpisodeMeta, EvalReport, StatusReport, TransitionBatch

LIMITS = Limits(n_actions=N_ACTIONS)


@pytest.mark.parametrize(
    "strategy", [transition_batches(), demo_batches(), weights_updates(), eval_reports(), learner_statuses()]
)
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_every_kind_round_trips(strategy, data) -> None:
    message = data.draw(strategy)
    decoded = decode(encode(message), LIMITS)
    assert same(decoded, message)


def test_registry_holds_the_five_kinds() -> None:
    assert {"transitions", "demos", "weights", "eval", "status"} <= set(KINDS)  # later modules add more


def test_decoded_arrays_are_read_only_views_of_the_received_bytes() -> None:
    wire = encode(small_transitions())
    batch = decode(wire, LIMITS)
    assert not batch.obs.flags.writeable
    assert isinstance(batch.obs.base, bytes)  # no copy after msgpack handed over the extension bytes
    assert batch.obs.ctypes.data % 8 == 0  # the padded header keeps the data aligned


@pytest.mark.parametrize(
    "array",
    [
        np.arange(6, dtype=">f8").reshape(2, 3),  # big-endian in, little-endian on the wire
        np.arange(12).reshape(3, 4)[:, ::2],  # not contiguous
        np.array(3.5, np.float32),  # zero dimensions
        np.zeros((0, 5), np.int32),
        np.zeros((3, 0, 2), np.float16),
        np.array([True, False]),
    ],
)
def test_array_extension_handles_layouts(array: np.ndarray) -> None:
    out = unpack_array(pack_array(array).data)
    assert out.shape == array.shape and np.array_equal(out, array)
    assert out.dtype == array.dtype.newbyteorder("<") or out.dtype == array.dtype


def test_constructor_converts_to_wire_dtypes() -> None:
    batch = small_transitions(action=[1, 2, 3, 4], reward=[0, 1, 2, 3])
    assert batch.action.dtype == np.int64 and batch.reward.dtype == np.float32
    assert batch.obs.dtype == np.float32 and batch.env_ids.dtype == np.int32 and len(batch) == 4


def test_demo_split_gives_minari_shaped_episodes() -> None:
    demo = DemoBatch(
        source="astar",
        episode_lengths=[2, 1],
        obs=np.arange(5 * 3).reshape(5, 3),
        actions=[0, 1, 2],
        rewards=[0, 0, 1],
        terminations=[False, True, True],
        truncations=[False, False, False],
        episodes=[
            EpisodeMeta(map_id="m", start=(1, 2), goal=(3, 4), seed=7),
            EpisodeMeta(map_id="", start=(0, 0), goal=(1, 1)),
        ],
    )
    (meta0, ep0), (meta1, ep1) = decode(encode(demo), LIMITS).split()
    assert meta0.seed == 7 and meta1.seed is None and meta1.start == (0, 0)
    assert ep0["observations"].shape == (3, 3) and ep0["actions"].tolist() == [0, 1]
    assert ep1["observations"].tolist() == [[9, 10, 11], [12, 13, 14]] and ep1["rewards"].tolist() == [1]


def test_numpy_scalars_in_json_fields_encode_as_numbers() -> None:
    report = EvalReport(
        model="nnql", policy_version=2, metrics={"unseen": {"spl": np.float64(0.5), "n": np.int64(3)}}
    )
    assert decode(encode(report), LIMITS).metrics == {"unseen": {"spl": 0.5, "n": 3}}


def test_status_losses_may_be_nan_but_rates_may_not() -> None:
    ok = decode(encode(StatusReport(losses={"td": math.nan})), LIMITS)
    assert math.isnan(ok.losses["td"])
    with pytest.raises(ProtocolError) as err:
        decode(encode(StatusReport(rates={"rx": math.inf})), LIMITS)
    assert err.value.reason == "nonfinite"


def test_encoding_an_unregistered_class_or_object_fails_clearly() -> None:
    class Stray(TransitionBatch):
        pass

    with pytest.raises(ProtocolError) as err:
        encode(Stray(**{f: getattr(small_transitions(), f) for f in small_transitions().to_body()}))
    assert err.value.reason == "kind"
    with pytest.raises(ProtocolError) as err:
        encode(EvalReport(model="m", policy_version=0, metrics={"f": {"x": object()}}))
    assert err.value.reason == "type"


def test_error_carries_reason_and_message() -> None:
    err = ProtocolError("shape", "obs has 3 rows")
    assert err.reason == "shape" and str(err) == "shape: obs has 3 rows" and isinstance(err, ValueError)
    with pytest.raises(ValueError):
        ProtocolError("no-such-reason", "x")
    assert {"malformed", "version", "kind", "dtype", "shape", "nonfinite", "action_range", "oversize"} <= set(
        REASONS
    )


def body_of(message) -> dict:
    return msgpack.unpackb(encode(message), ext_hook=lambda code, data: msgpack.ExtType(code, data))["b"]


def rejected(data: bytes, limits: Limits = LIMITS) -> ProtocolError:
    with pytest.raises(ProtocolError) as err:
        decode(data, limits)
    return err.value


CASES = {
    "nan obs": ("nonfinite", lambda b: b | {"obs": np.full((4, 11), np.nan, np.float32)}),
    "inf reward": ("nonfinite", lambda b: b | {"reward": np.array([0, np.inf, 0, 0], np.float32)}),
    "float64 obs": ("dtype", lambda b: b | {"obs": np.zeros((4, 11))}),
    "int32 actions": ("dtype", lambda b: b | {"action": np.zeros(4, np.int32)}),
    "action too big": ("action_range", lambda b: b | {"action": np.array([0, 1, N_ACTIONS, 0])}),
    "negative action": ("action_range", lambda b: b | {"action": np.array([0, -1, 0, 0])}),
    "next_obs shape": ("shape", lambda b: b | {"next_obs": np.zeros((4, 10), np.float32)}),
    "reward rows": ("shape", lambda b: b | {"reward": np.zeros(3, np.float32)}),
    "obs 1-d": ("shape", lambda b: b | {"obs": np.zeros(44, np.float32)}),
    "missing field": ("field", lambda b: {k: v for k, v in b.items() if k != "reward"}),
    "extra field": ("field", lambda b: b | {"secret": 1}),
    "actor not str": ("type", lambda b: b | {"actor": 7}),
    "obs not array": ("type", lambda b: b | {"obs": [[0.0] * 11] * 4}),
    "empty actor": ("string", lambda b: b | {"actor": ""}),
    "long model": ("string", lambda b: b | {"model": "m" * 300}),
    "control chars": ("string", lambda b: b | {"model": "a\x00b"}),
    "negative version": ("range", lambda b: b | {"policy_version": -1}),
    "bool version": ("type", lambda b: b | {"policy_version": True}),
}


@pytest.mark.parametrize("case", CASES)
def test_bad_transition_bodies_are_rejected_with_their_reason(case: str) -> None:
    reason, mutate = CASES[case]
    body = mutate(body_of(small_transitions()))
    body = {k: (unpack_array(v.data) if isinstance(v, msgpack.ExtType) else v) for k, v in body.items()}
    assert rejected(raw_envelope("transitions", body)).reason == reason


def test_envelope_checks() -> None:
    body = {
        k: (unpack_array(v.data) if isinstance(v, msgpack.ExtType) else v)
        for k, v in body_of(small_transitions()).items()
    }
    assert rejected(raw_envelope("transitions", body, version=2)).reason == "version"
    assert rejected(raw_envelope("transitions", body, version="1")).reason == "version"
    assert rejected(raw_envelope("teleport", body)).reason == "kind"
    assert rejected(raw_envelope("transitions", body, extra=1)).reason == "malformed"
    assert rejected(msgpack.packb([1, 2, 3])).reason == "malformed"
    assert (
        rejected(
            msgpack.packb(
                {"v": 1, "k": "transitions", "s": "x", "n": -1, "b": body}, default=lambda a: pack_array(a)
            )
        ).reason
        == "range"
    )
    assert rejected(raw_envelope("status", [])).reason == "type"
    assert rejected("not bytes").reason == "type"


def test_size_and_nesting_limits() -> None:
    wire = encode(small_transitions(n=64))
    assert rejected(wire, Limits(n_actions=N_ACTIONS, max_message_bytes=len(wire) - 1)).reason == "oversize"
    assert rejected(wire, Limits(n_actions=N_ACTIONS, max_batch=63)).reason == "oversize"
    assert (
        rejected(
            encode(small_transitions(obs=np.zeros((4, 30)), next_obs=np.zeros((4, 30)))),
            Limits(max_obs_dim=20),
        ).reason
        == "shape"
    )
    deep: object = 1
    for _ in range(20):
        deep = {"x": deep}
    assert rejected(encode(EvalReport(model="m", policy_version=0, metrics={"f": deep}))).reason == "oversize"
    many = StatusReport(counters={f"c{i}": i for i in range(100)})
    assert rejected(encode(many), Limits(max_items=50)).reason == "oversize"
    assert (
        rejected(b"\x91" * 100_000 + b"\x00").reason == "malformed"
    )  # 100k nested arrays: no crash, no hang


def test_demo_consistency_checks() -> None:
    good = DemoBatch(
        source="human",
        episode_lengths=[2],
        obs=np.zeros((3, 4)),
        actions=[0, 1],
        rewards=[0, 1],
        terminations=[False, True],
        truncations=[False, False],
        episodes=[EpisodeMeta(map_id="m", start=(0, 0), goal=(1, 1))],
    )
    decode(encode(good), LIMITS)
    body = {
        k: (unpack_array(v.data) if isinstance(v, msgpack.ExtType) else v) for k, v in body_of(good).items()
    }
    assert rejected(raw_envelope("demos", body | {"source": "oracle"})).reason == "string"
    assert rejected(raw_envelope("demos", body | {"obs": np.zeros((2, 4), np.float32)})).reason == "shape"
    assert (
        rejected(raw_envelope("demos", body | {"episode_lengths": np.array([0], np.int32)})).reason == "shape"
    )
    assert rejected(raw_envelope("demos", body | {"episodes": []})).reason == "shape"
    bad_cell = [body["episodes"][0] | {"start": [0, -3]}]
    assert rejected(raw_envelope("demos", body | {"episodes": bad_cell})).reason == "range"
    bad_meta = [body["episodes"][0] | {"color": "red"}]
    assert rejected(raw_envelope("demos", body | {"episodes": bad_meta})).reason == "field"


def test_array_extension_corruption() -> None:
    good = pack_array(np.zeros((2, 3), np.float32)).data
    with pytest.raises(ProtocolError, match="shape"):
        unpack_array(good[:-4])
    with pytest.raises(ProtocolError, match="dtype"):
        unpack_array(bytes([99]) + good[1:])
    with pytest.raises(ProtocolError, match="malformed"):
        unpack_array(pack_array(np.array([True, False])).data[:-1] + b"\x02")
    with pytest.raises(ProtocolError, match="malformed"):
        decode(msgpack.packb({"v": 1, "k": "status", "s": "", "n": 0, "b": msgpack.ExtType(7, b"xx")}))


@settings(max_examples=30, deadline=None)
@given(message=any_message)
def test_encoding_is_deterministic(message) -> None:
    assert encode(message) == encode(decode(encode(message), LIMITS))

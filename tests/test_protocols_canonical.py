"""protocols.fastpath against the general codec path.

The fast decoder may only ever accept: whenever it returns a message, the general path (msgpack and the
schema checks) must return an equal one, and whatever it declines the general path decides, so
``decode`` as a whole answers exactly as the general path does (same message, or a ProtocolError with
the same reason). The fast encoder must write the general encoder's bytes.
"""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from wire_helpers import N_ACTIONS, names, same, small_transitions, transition_batches

from protocols.codec import _decode, _encode, decode, encode
from protocols.errors import ProtocolError
from protocols.fastpath import decode_transitions
from protocols.limits import Limits
from protocols.messages import EvalReport, Message, TransitionBatch

LIMITS = Limits(n_actions=N_ACTIONS)
LIMIT_VARIANTS = (
    LIMITS,
    Limits(),  # n_actions None: only actions >= 0
    Limits(n_actions=1),
    Limits(n_actions=N_ACTIONS, max_items=9),  # the body map's 10 entries are too many
    Limits(n_actions=N_ACTIONS, max_items=10),
    Limits(n_actions=N_ACTIONS, max_batch=3),
    Limits(n_actions=N_ACTIONS, max_obs_dim=2),
    Limits(n_actions=N_ACTIONS, max_string=2),
    Limits(n_actions=N_ACTIONS, max_string=4),
)
INTS = st.sampled_from([0, 1, 127, 128, 255, 256, 65535, 65536, 2**32 - 1, 2**32, 2**63 - 1]) | st.integers(
    0, 2**63 - 1
)
SETTINGS = settings(max_examples=100, deadline=None)
moderate = st.floats(-(2.0**50), 2.0**50, width=32)  # no float32 dot product of 40 x 16 of these overflows
ARRAYS = ("env_ids", "obs", "action", "reward", "next_obs", "terminated", "truncated")


def general(wire: bytes, limits: Limits) -> Message | ProtocolError:
    try:
        return _decode(wire, limits, fast=False)
    except ProtocolError as exc:
        return exc


def agree(wire: bytes, limits: Limits = LIMITS) -> TransitionBatch | None:
    """The fast decoder's answer, after checking it and ``decode``'s against the general path's."""
    fast = decode_transitions(wire, limits)
    reference = general(wire, limits)
    if fast is not None:
        assert isinstance(reference, TransitionBatch), (
            f"fast path accepted what the general one rejects: {reference}"
        )
        assert same(fast, reference)
        for name in ARRAYS:
            array = getattr(fast, name)
            assert array.dtype == getattr(reference, name).dtype and not array.flags.writeable
            assert array.dtype.itemsize == 1 or array.ctypes.data % 8 == 0  # aligned as the general path's
    try:
        whole: Message | ProtocolError = decode(wire, limits)
    except ProtocolError as exc:
        whole = exc
    if isinstance(reference, ProtocolError):
        assert isinstance(whole, ProtocolError) and (whole.reason, whole.message) == (
            reference.reason,
            reference.message,
        )
    else:
        assert same(whole, reference)
    return fast


@st.composite
def batches(draw, max_rows: int = 40) -> TransitionBatch:
    """Valid batches with integers of every msgpack width and strings of every length class."""
    n, dim = draw(st.integers(0, max_rows)), draw(st.integers(1, 16))
    text = names | st.sampled_from(["a" * 31, "b" * 32, "é" * 200, "𝄞" * 256, "x" * 256])
    return TransitionBatch(
        actor=draw(text),
        model=draw(text),
        policy_version=draw(INTS),
        env_ids=draw(hnp.arrays(np.int32, n)),
        obs=draw(hnp.arrays(np.float32, (n, dim), elements=moderate)),
        action=draw(hnp.arrays(np.int64, n, elements=st.integers(0, N_ACTIONS - 1))),
        reward=draw(hnp.arrays(np.float32, n, elements=moderate)),
        next_obs=draw(hnp.arrays(np.float32, (n, dim), elements=moderate)),
        terminated=draw(hnp.arrays(np.bool_, n)),
        truncated=draw(hnp.arrays(np.bool_, n)),
        sender=draw(st.just("") | text),
        seq=draw(INTS),
    )


@SETTINGS
@given(batch=batches() | transition_batches())
def test_valid_batches_take_the_fast_path_and_equal_the_general_one(batch: TransitionBatch) -> None:
    wire = encode(batch)
    assert wire == _encode(batch, fast=False)
    overflow = not (
        np.isfinite(np.vdot(batch.obs, batch.next_obs)) and np.isfinite(np.vdot(batch.reward, batch.reward))
    )
    assert (agree(wire) is None) == overflow  # finite values whose dot product overflows: the general path
    assert same(decode(wire, LIMITS), batch)


@settings(max_examples=40, deadline=None)
@given(batch=batches(max_rows=12), limits=st.sampled_from(LIMIT_VARIANTS))
def test_limits_bind_the_fast_path_as_the_general_one(batch: TransitionBatch, limits: Limits) -> None:
    agree(encode(batch), limits)


@pytest.mark.parametrize("n", [1, 2, 1024])
def test_arrays_are_aligned_whatever_the_offsets(n: int) -> None:
    """Arrays start at offsets that move with the lengths of the strings and integers before them."""
    for seq, sender in ((0, ""), (200, "a"), (70_000, "ab"), (2**40, "abc"), (5, "abcd"), (9, "abcdefg")):
        batch = small_transitions(n=n, sender=sender, seq=seq)
        message = agree(encode(batch))
        assert message is not None and same(message, batch)


def test_arrays_are_views_of_the_message_where_aligned() -> None:
    wire = encode(small_transitions(n=8))
    message = decode_transitions(wire, LIMITS)
    bases = [getattr(message, name).base for name in ("obs", "terminated", "truncated")]
    assert all(isinstance(base, bytes) for base in bases)
    assert any(base is wire for base in bases)  # the boolean arrays never need a copy


def small_wire(**overrides) -> bytes:
    return encode(small_transitions(n=3, dim=2, sender="s", seq=7, **overrides))


def data_ranges(wire: bytes) -> list[tuple[int, int]]:
    """(start, end) of each array's data in ``wire``, from its key and extension header."""
    ranges = []
    for name in ARRAYS:
        ext = wire.index(msgpack.packb(name)) + len(msgpack.packb(name))
        assert wire[ext] == 0xC9 and wire[ext + 5] == 1
        payload = int.from_bytes(wire[ext + 1 : ext + 5], "big")
        header = 16 if name in ("obs", "next_obs") else 8
        ranges.append((ext + 6 + header, ext + 6 + payload))
    return ranges


def test_every_change_of_a_structural_byte() -> None:
    """Every value of every byte outside the array data: headers, keys, strings, integers, templates."""
    wire = small_wire()
    inside = {i for start, end in data_ranges(wire) for i in range(start, end)}
    accepted = 0
    for offset in sorted(set(range(len(wire))) - inside):
        for value in range(256):
            if value != wire[offset]:
                mutated = wire[:offset] + bytes([value]) + wire[offset + 1 :]
                accepted += agree(mutated) is not None
    assert accepted  # e.g. other printable characters in the strings, other sequence numbers


def test_every_truncation_and_trailing_bytes() -> None:
    wire = small_wire()
    for size in range(len(wire)):
        assert agree(wire[:size]) is None
    for junk in (b"\x00", b"\xc0", wire):
        assert agree(wire + junk) is None


@settings(max_examples=300, deadline=None)
@given(flips=st.lists(st.integers(0, 2**40), min_size=1, max_size=6))
def test_bit_flips(flips: list[int]) -> None:
    wire = bytearray(small_wire())
    for flip in flips:
        bit = flip % (8 * len(wire))
        wire[bit // 8] ^= 1 << (bit % 8)
    agree(bytes(wire))


def patched(wire: bytes, field: int, index: int, value: bytes) -> bytes:
    start = data_ranges(wire)[field][0] + index * len(value)
    return wire[:start] + value + wire[start + len(value) :]


FIELD = {name: i for i, name in enumerate(ARRAYS)}


@pytest.mark.parametrize("field", ["obs", "next_obs", "reward"])
@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf, 3e38])
def test_non_finite_and_huge_floats(field: str, value: float) -> None:
    wire = small_wire()
    for index in (0, 1, 2):
        fast = agree(patched(wire, FIELD[field], index, np.float32(value).tobytes()))
        if not np.isfinite(value):
            assert fast is None
    huge = encode(small_transitions(n=3, dim=2, obs=np.full((3, 2), 3e38), next_obs=np.full((3, 2), 3e38)))
    assert agree(huge) is None  # finite, but the dot product overflows: the general path decides
    assert isinstance(general(huge, LIMITS), TransitionBatch)


@pytest.mark.parametrize("action", [N_ACTIONS, N_ACTIONS + 1, 255, 2**62, -1, -(2**63), 2**63 - 1])
def test_actions_out_of_range(action: int) -> None:
    for limits in LIMIT_VARIANTS[:3]:
        for index in (0, 2):
            agree(patched(small_wire(), FIELD["action"], index, np.int64(action).tobytes()), limits)


@pytest.mark.parametrize("field", ["terminated", "truncated"])
@pytest.mark.parametrize("value", [2, 3, 0x80, 0xFF])
def test_booleans_other_than_0_and_1(field: str, value: int) -> None:
    for index in (0, 2):
        assert agree(patched(small_wire(), FIELD[field], index, bytes([value]))) is None


@pytest.mark.parametrize(
    "overrides",
    [
        {"actor": "a" * 257},
        {"actor": "𝄞" * 257},
        {"model": ""},
        {"actor": "a\nb"},
        {"model": "\x00"},
        {"sender": "\u200b"},
        {"sender": "s" * 257},
        {"policy_version": 2**63},
        {"seq": 2**64 - 1},
        {"seq": -1},
        {"obs": np.ones((3, 0)), "next_obs": np.ones((3, 0))},
        {"obs": np.ones((3, 5000)), "next_obs": np.ones((3, 5000))},
    ],
)
def test_bad_header_values(overrides: dict) -> None:
    wire = encode(small_transitions(n=3, dim=2, **({"sender": "s", "seq": 7} | overrides)))
    assert agree(wire) is None
    assert isinstance(general(wire, LIMITS), ProtocolError)


@pytest.mark.parametrize(
    ("limits", "fields", "accepted"),
    [
        (Limits(max_batch=3), {"n": 3}, True),
        (Limits(max_batch=3), {"n": 4}, False),
        (Limits(max_obs_dim=2), {"dim": 2}, True),
        (Limits(max_obs_dim=2), {"dim": 3}, False),
        (Limits(max_string=4), {"actor": "abcd", "model": "efgh", "sender": "ijkl", "env": "mnop"}, True),
        (Limits(max_string=4), {"actor": "𝄞𝄞𝄞𝄞", "model": "é", "sender": ""}, True),  # 4 x 4 bytes
        (Limits(max_string=4), {"actor": "abcde"}, False),
        (Limits(max_string=4), {"env": "abcde"}, False),
        (Limits(max_string=4), {"model": "abcde"}, False),
        (Limits(max_string=4), {"sender": "abcde"}, False),
        (Limits(max_string=3), {}, False),  # msgpack's max_str_len (4 x 3 bytes) binds "policy_version" too
        (Limits(), {"actor": ""}, False),
        (Limits(max_items=11), {}, True),
        (Limits(max_items=10), {}, False),
        (Limits(n_actions=5), {"action": [4, 0, 1]}, True),
        (Limits(n_actions=5), {"action": [0, 5, 1]}, False),
        (Limits(), {"action": [2**63 - 1, 0, 0]}, True),
        (Limits(), {"action": [0, 0, -1]}, False),
        (Limits(), {"reward": [0.0, 0.0, np.inf]}, False),
    ],
)
def test_limits_at_their_bounds(limits: Limits, fields: dict, accepted: bool) -> None:
    fields = {"n": 3, "dim": 2, "actor": "a", "model": "m", "sender": "s", "env": "e"} | fields
    wire = encode(small_transitions(**fields))
    assert (agree(wire, limits) is not None) == accepted
    assert isinstance(general(wire, limits), TransitionBatch) == accepted


def test_other_kinds_and_buffers_are_declined() -> None:
    report = encode(EvalReport(model="m", policy_version=1, metrics={"f": {"success": 1.0}}))
    assert decode_transitions(report, LIMITS) is None
    wire = small_wire()
    assert decode_transitions(bytearray(wire), LIMITS) is None  # would give writable arrays
    assert decode_transitions(memoryview(wire), LIMITS) is None
    assert same(decode(bytearray(wire), LIMITS), decode(wire, LIMITS))
    padded = bytearray(wire)
    obs_header = data_ranges(wire)[1][0] - 4  # the 2-d header's zero padding
    padded[obs_header] = 1
    assert agree(bytes(padded)) is None and isinstance(general(bytes(padded), LIMITS), TransitionBatch)


def replace(batch: TransitionBatch, **fields) -> TransitionBatch:
    for name, value in fields.items():
        setattr(batch, name, value)  # after construction: no conversion to the wire dtypes
    return batch


@pytest.mark.parametrize(
    "fields",
    [
        {"obs": np.ones((3, 2))},
        {"obs": np.ones((3, 2), ">f4")},
        {"obs": np.ones((3, 4), np.float32)[:, ::2]},
        {"obs": np.asfortranarray(np.arange(6, dtype=np.float32).reshape(3, 2))},
        {"obs": np.ones(6, np.float32)},
        {"next_obs": np.ones((3, 3), np.float32)},
        {"action": np.arange(3, dtype=np.int32)},
        {"reward": np.ones(4, np.float32)},
        {"terminated": np.zeros(3, np.uint8)},
        {"truncated": [False] * 3},
        {"env_ids": np.arange(6, dtype=np.int32)[::2]},
        {"policy_version": np.int64(3)},
        {"sender": 5},
        {"actor": object()},
        {"obs": np.ones((3, 2), object)},
    ],
)
def test_encoding_non_canonical_batches_writes_the_general_bytes(fields: dict) -> None:
    batch = replace(small_transitions(n=3, dim=2), **fields)
    try:
        wire = encode(batch)
    except ProtocolError as exc:
        with pytest.raises(ProtocolError) as reference:
            _encode(batch, fast=False)
        assert (exc.reason, exc.message) == (reference.value.reason, reference.value.message)
    else:
        assert wire == _encode(batch, fast=False)
        agree(wire)

"""The hot message, TransitionBatch, read and written straight from and to its canonical bytes.

Why this exists: actors send a TransitionBatch of ~1024 transitions many times a second, and the
learner's subscriber shares the machine's cores with Zenoh. Through the general path (``msgpack.unpackb``
with a Python hook per array extension, then the schema checks on the unpacked maps) decoding one costs
several times what Zenoh spends moving it, so the codec, not the transport, set the end-to-end rate
(bench/wire.py, part (b)).

Our encoder always writes one byte layout for a TransitionBatch (DESIGN.md's envelope; nothing here
changes the wire)::

    map(5) "v" 1  "k" "transitions"  "s" <str>  "n" <uint>  "b" map(10)
        "actor" <str>  "model" <str>  "policy_version" <uint>
        "env_ids" "obs" "action" "reward" "next_obs" "terminated" "truncated": each an ext 32 of type 1
        (protocols.arrays: dtype code, ndim, two zero bytes, u32 shape, zero padding to 8, raw data)

Given the batch size N and the observation size D, everything after ``policy_version`` except the array
data is constant. :func:`decode_transitions` compares those constant parts with byte templates cached
per (N, D), reads the three strings and two integers itself, makes the arrays, and applies every check
of ``TransitionBatch.read_body`` and of the envelope. :func:`encode_transitions` writes the same bytes
as the general encoder from the cached templates, without building the body map.

Arrays are read-only views of the received bytes where their data is 8-byte aligned, and aligned
copies of their bytes where it is not, so decoded arrays are aligned whichever path decoded them (the
general path views msgpack's copy of each extension payload). Where an array falls depends on the
lengths of the strings and integers before it, and the arrays' offsets differ modulo 8, so most
messages copy most of their float and integer data (about 3 us of the ~20 us a decode costs here).

How it stays safe: the fast decoder only ever *accepts* a message or returns None; it never rejects.
Anything that is not exactly the canonical layout (another kind, a string or integer in another msgpack
type than str or unsigned int, a non-zero padding byte, trailing bytes, a bytearray or memoryview, limits
so small that msgpack itself would refuse the layout) or that fails any check returns None, and the
general path then decides and gives the reason code. Accepting is sound because a canonical message is
a msgpack document whose unpacked value is exactly what was parsed here, and the value checks are
read_body's. tests/test_protocols_canonical.py holds the two paths equal on random batches and on
mutated bytes (every value of every structural byte, truncations, bit flips, bad values, limits at
their bounds) and the encoder byte-equal to the general one.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from math import isfinite

import msgpack
import numpy as np

from protocols.arrays import _array_head
from protocols.checks import INT64_MAX
from protocols.errors import ProtocolError
from protocols.limits import Limits
from protocols.messages import TransitionBatch

_ARRAY_FIELDS = ("env_ids", "obs", "action", "reward", "next_obs", "terminated", "truncated")
_WIRE_DTYPES = tuple(np.dtype(s) for s in ("<i4", "<f4", "<i8", "<f4", "<f4", "|b1", "|b1"))
_VIEW_DTYPES = tuple(np.dtype(s) for s in ("<i4", "<f4", "<u8", "<f4", "<f4", "|b1", "|b1"))
"""The arrays' dtypes as first viewed: actions as unsigned (for the range check), then as int64."""
_I64 = np.dtype("<i8")
_NDARRAYS = (np.ndarray,) * len(_ARRAY_FIELDS)
_OBS_FIELDS = frozenset({"obs", "next_obs"})
_MAX_LAYOUTS = 256
"""Most (N, D) layouts remembered (bounds memory whatever shapes arrive)."""


def _packed(*items: object) -> bytes:
    return b"".join(msgpack.packb(item) for item in items)


_HEAD = b"\x85" + _packed("v", TransitionBatch.VERSION, "k", TransitionBatch.KIND, "s")
_SEQ_KEY = _packed("n")
_BODY_START = b"\x8a".join((_packed("b"), _packed("actor")))  # "b", the body's map header, "actor"
_MODEL_KEY = _packed("model")
_VERSION_KEY = _packed("policy_version")
_KEY_SIZES = tuple(len(_packed(name)) for name in _ARRAY_FIELDS)
_LONGEST_KEY = max(map(len, ("transitions", "policy_version", *_ARRAY_FIELDS)))
"""Longest string of the layout, in bytes (msgpack's max_str_len applies to it as to any other)."""
_EXT_HEAD = 6  # 0xc9, u32 payload length, type
_ENV_IDS_DATA = _KEY_SIZES[0] + _EXT_HEAD + 8  # offset of env_ids' data from its key (shape[0] just before)
_OBS_DIM = _KEY_SIZES[1] + _EXT_HEAD + 8  # offset of obs' shape[1] from its key
_U32 = struct.Struct("<I")
_UINT_SIZES = {0xCC: 1, 0xCD: 2, 0xCE: 4, 0xCF: 8}
_STR_SIZES = {0xD9: 1, 0xDA: 2, 0xDB: 4}


class _Layout:
    """The constant parts of the array section for one (N, D), offsets from the env_ids key."""

    __slots__ = ("flags_at", "flags_rest", "parts", "plans", "shapes", "size", "templates")

    def __init__(self, n: int, d: int) -> None:
        templates, arrays, at = [], [], 0
        for name, dtype, view in zip(_ARRAY_FIELDS, _WIRE_DTYPES, _VIEW_DTYPES, strict=True):
            shape = (n, d) if name in _OBS_FIELDS else (n,)
            template = _packed(name) + _array_head(dtype, shape)
            templates.append((at, template))
            at += len(template)
            nbytes = math.prod(shape) * dtype.itemsize
            arrays.append((shape, view, at, at + nbytes, dtype.alignment > 1))
            at += nbytes
        self.size = at
        self.templates = tuple(templates)
        """(offset, the field's key and its extension and array headers), in wire order."""
        self.parts = tuple(template for _, template in templates)
        self.shapes = tuple(shape for shape, *_ in arrays)
        self.plans = tuple(
            tuple(
                (shape, dtype, start, end if needs_alignment and (residue + start) % 8 else 0)
                for shape, dtype, start, end, needs_alignment in arrays
            )
            for residue in range(8)
        )
        """By the section's start modulo 8: each array's (shape, dtype to view it with, start, end of the
        bytes to copy, or 0 where a view of the message is aligned as it is)."""
        self.flags_at = arrays[5][2]
        """Where the two boolean arrays and the truncated template between them start."""
        self.flags_rest = templates[6][1].translate(None, b"\x00\x01")
        """What deleting every 0 and 1 byte from there to the end must leave."""

    @staticmethod
    def size_for(n: int, d: int) -> int:
        """``size`` without building the templates (array headers: 8 bytes in 1-d, 16 in 2-d)."""
        headers = sum(_KEY_SIZES) + _EXT_HEAD * 7 + 8 * 5 + 16 * 2
        return headers + n * (4 + 8 + 4 + 1 + 1) + 2 * 4 * n * d


_LAYOUTS: dict[tuple[int, int], _Layout] = {}


def _layout(n: int, d: int) -> _Layout:
    layout = _LAYOUTS.get((n, d))
    if layout is None:
        layout = _Layout(n, d)
        if len(_LAYOUTS) < _MAX_LAYOUTS:
            _LAYOUTS[(n, d)] = layout
    return layout


def _uint(data: bytes, at: int) -> tuple[int, int]:
    """(value, end) of a msgpack unsigned integer at ``at``; (-1, at) if there is none."""
    marker = data[at]
    if marker < 0x80:
        return marker, at + 1
    size = _UINT_SIZES.get(marker)
    if size is None:
        return -1, at
    end = at + 1 + size
    if end > len(data):
        return -1, at
    return int.from_bytes(data[at + 1 : end], "big"), end


def _str(data: bytes, at: int, max_bytes: int) -> tuple[str | None, int]:
    """(value, end) of a msgpack string of at most ``max_bytes`` bytes at ``at``; (None, at) otherwise.
    Invalid UTF-8 raises UnicodeDecodeError (as msgpack's own strict decoding would)."""
    marker = data[at]
    if 0xA0 <= marker <= 0xBF:
        start, size = at + 1, marker & 0x1F
    else:
        width = _STR_SIZES.get(marker)
        if width is None:
            return None, at
        start = at + 1 + width
        size = int.from_bytes(data[at + 1 : start], "big")
    end = start + size
    if size > max_bytes or end > len(data):
        return None, at
    return data[start:end].decode(), end


def decode_transitions(data: bytes, limits: Limits) -> TransitionBatch | None:
    """The TransitionBatch in ``data`` if it is in the canonical layout and passes every check the general
    decoder applies (``limits.max_message_bytes`` excepted: the caller checks it first); else None."""
    if type(data) is not bytes or not data.startswith(_HEAD):
        return None
    try:
        return _decode(data, limits)
    except Exception:  # any surprise means "not the canonical layout": the general path says what
        return None


def _decode(data: bytes, limits: Limits) -> TransitionBatch | None:
    max_string, max_bytes = limits.max_string, 4 * limits.max_string  # msgpack's max_str_len in decode
    if limits.max_items < 10 or max_bytes < _LONGEST_KEY:  # msgpack's limits bind keys and maps too
        return None
    sender, at = _str(data, len(_HEAD), max_bytes)
    if sender is None or len(sender) > max_string or not sender.isprintable():
        return None
    if not data.startswith(_SEQ_KEY, at):
        return None
    seq, at = _uint(data, at + len(_SEQ_KEY))
    if not 0 <= seq <= INT64_MAX or not data.startswith(_BODY_START, at):
        return None
    actor, at = _str(data, at + len(_BODY_START), max_bytes)
    if actor is None or not 0 < len(actor) <= max_string or not actor.isprintable():
        return None
    if not data.startswith(_MODEL_KEY, at):
        return None
    model, at = _str(data, at + len(_MODEL_KEY), max_bytes)
    if model is None or not 0 < len(model) <= max_string or not model.isprintable():
        return None
    if not data.startswith(_VERSION_KEY, at):
        return None
    version, at = _uint(data, at + len(_VERSION_KEY))
    if not 0 <= version <= INT64_MAX:
        return None

    # The array section: N from env_ids' header, D from obs' header; both then checked in full.
    n = _U32.unpack_from(data, at + _ENV_IDS_DATA - 4)[0]
    d = _U32.unpack_from(data, at + _ENV_IDS_DATA + 4 * n + _OBS_DIM)[0]
    if n > limits.max_batch or not 1 <= d <= limits.max_obs_dim or len(data) - at != _Layout.size_for(n, d):
        return None
    layout = _layout(n, d)
    for offset, template in layout.templates:
        if not data.startswith(template, at + offset):
            return None
    flags_at = at + layout.flags_at
    if data[flags_at:].translate(None, b"\x00\x01") != layout.flags_rest:  # booleans only 0 or 1
        return None

    # Arrays are read-only views of ``data`` where their data is 8-byte aligned (bytes objects' data is,
    # as the general decoder assumes of msgpack's extension payloads), else aligned copies: decoded
    # arrays are always aligned, whichever path decoded them.
    ndarray = np.ndarray
    arrays = [
        ndarray(shape, dtype, data[at + start : at + end]) if end else ndarray(shape, dtype, data, at + start)
        for shape, dtype, start, end in layout.plans[at & 7]
    ]
    env_ids, obs, actions, reward, next_obs, terminated, truncated = arrays
    # Finite floats: a dot product is finite only if every term is (inf * 0 and inf - inf are NaN, NaN
    # propagates); an overflowing sum of finite values returns None and the general path decides.
    # np.vdot, unlike np.dot, sets no floating-point error flags, so no errstate is needed around it.
    if not (isfinite(np.vdot(obs, next_obs)) and isfinite(np.vdot(reward, reward))):
        return None
    if n:  # actions in [0, n_actions): negative ones wrap to >= 2**63 as unsigned
        bound = INT64_MAX + 1 if limits.n_actions is None else limits.n_actions
        if actions.item(actions.argmax()) >= bound:
            return None
    message = object.__new__(TransitionBatch)
    message.__dict__.update(
        env_ids=env_ids,
        obs=obs,
        action=actions.view(_I64),
        reward=reward,
        next_obs=next_obs,
        terminated=terminated,
        truncated=truncated,
        actor=actor,
        model=model,
        policy_version=version,
        sender=sender,
        seq=seq,
    )
    return message


def encode_transitions(batch: TransitionBatch, pack: Callable[[object], bytes]) -> bytes | None:
    """The general encoder's bytes for ``batch`` (``pack`` packs one value, as it does there), written
    from cached templates; None if an array is not a numpy array of its wire dtype, shape and C order
    (the general encoder then handles it, or raises)."""
    obs = batch.obs
    if type(obs) is not np.ndarray or obs.ndim != 2:
        return None
    env_ids, action, reward, next_obs = batch.env_ids, batch.action, batch.reward, batch.next_obs
    terminated, truncated = batch.terminated, batch.truncated
    arrays = (env_ids, obs, action, reward, next_obs, terminated, truncated)
    if tuple(map(type, arrays)) != _NDARRAYS:
        return None
    try:
        layout = _layout(*obs.shape)
    except ProtocolError:  # a shape the array header cannot hold
        return None
    if (
        env_ids.dtype,
        obs.dtype,
        action.dtype,
        reward.dtype,
        next_obs.dtype,
        terminated.dtype,
        truncated.dtype,
    ) != _WIRE_DTYPES or (
        env_ids.shape,
        obs.shape,
        action.shape,
        reward.shape,
        next_obs.shape,
        terminated.shape,
        truncated.shape,
    ) != layout.shapes:
        return None
    t0, t1, t2, t3, t4, t5, t6 = layout.parts
    try:  # join takes an array's bytes only through a simple buffer, which numpy grants C-ordered arrays
        return b"".join(
            (
                _HEAD,
                pack(batch.sender),
                _SEQ_KEY,
                pack(batch.seq),
                _BODY_START,
                pack(batch.actor),
                _MODEL_KEY,
                pack(batch.model),
                _VERSION_KEY,
                pack(batch.policy_version),
                t0,
                env_ids,
                t1,
                obs,
                t2,
                action,
                t3,
                reward,
                t4,
                next_obs,
                t5,
                terminated,
                t6,
                truncated,
            )
        )
    except TypeError:
        return None

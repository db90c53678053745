"""Bytes <-> messages: a msgpack envelope, numpy arrays as an extension type.

Envelope (a msgpack map)::

    {"v": schema version, "k": kind, "s": sender, "n": sequence number, "b": body map}

:func:`decode` trusts nothing: size, layout, kind, version and every body field
are checked, and any failure is a :class:`ProtocolError` with a reason code.
Nothing is ever unpickled. TransitionBatches, the hot kind, are written and read
straight from their canonical bytes by :mod:`protocols.fastpath` (same bytes, same
checks); whatever it declines goes through msgpack and the schema checks here.
"""

from __future__ import annotations

import dataclasses
import threading

import msgpack
import numpy as np

from protocols.arrays import array_parts, default, ext_hook
from protocols.checks import BodyReader, check_int, check_string, quiet_float_errors
from protocols.errors import ProtocolError
from protocols.fastpath import decode_transitions, encode_transitions
from protocols.limits import DEFAULT_LIMITS, Limits
from protocols.messages import KINDS, Message, TransitionBatch

_ENVELOPE_KEYS = frozenset("vksnb")
_local = threading.local()
_FIELD_NAMES: dict[type, frozenset[str]] = {}


def _packer() -> msgpack.Packer:
    """This thread's packer: one long-lived internal buffer (``msgpack.packb`` allocates and frees
    one per call). Only small values go through it; arrays are spliced in by :func:`_write_map`."""
    packer = getattr(_local, "packer", None)
    if packer is None:
        packer = _local.packer = msgpack.Packer(default=default, use_bin_type=True)
    return packer


def encode(message: Message) -> bytes:
    """The wire bytes of ``message`` (validated by the receiver, not here)."""
    return _encode(message, fast=True)


def _encode(message: Message, *, fast: bool) -> bytes:
    """``encode``; ``fast=False`` skips the TransitionBatch templates of :mod:`protocols.fastpath`
    (the general path, which the tests hold the fast one byte-equal to)."""
    cls = type(message)
    if KINDS.get(cls.KIND) is not cls:
        raise ProtocolError("kind", f"{cls.__name__} is not a registered message kind")
    pack = _packer().pack
    try:
        if fast and cls is TransitionBatch:
            wire = encode_transitions(message, pack)
            if wire is not None:
                return wire
        parts: list[bytes | memoryview] = [
            _envelope_head(cls),  # {"v": VERSION, "k": KIND, "s":
            pack(message.sender),
            _N_KEY,
            pack(message.seq),
            _B_KEY,
        ]
        _write_map(message.to_body(), pack, parts)
        return b"".join(parts)
    except ProtocolError:
        raise
    except (TypeError, ValueError, OverflowError) as exc:
        raise ProtocolError("type", f"cannot encode {message.KIND}: {exc}") from exc


_N_KEY, _B_KEY = msgpack.packb("n"), msgpack.packb("b")
_ENVELOPE_HEADS: dict[type, bytes] = {}
_PACKED_KEYS: dict[str, bytes] = {}


def _envelope_head(cls: type[Message]) -> bytes:
    """The constant start of ``cls``'s envelopes: the map header, version, kind and the sender key."""
    head = _ENVELOPE_HEADS.get(cls)
    if head is None:
        packer = msgpack.Packer(use_bin_type=True, autoreset=False)
        packer.pack_map_header(5)
        for item in ("v", cls.VERSION, "k", cls.KIND, "s"):
            packer.pack(item)
        head = _ENVELOPE_HEADS[cls] = packer.bytes()
    return head


def _write_map(mapping: dict, pack, parts: list[bytes | memoryview]) -> None:
    """Pack ``mapping`` into ``parts``, splicing arrays (at this level or in maps of arrays) in place."""
    parts.append(_map_header(len(mapping)))
    for key, value in mapping.items():
        packed_key = _PACKED_KEYS.get(key)
        if packed_key is None:
            packed_key = pack(key)
            if type(key) is str and len(_PACKED_KEYS) < 4096:
                _PACKED_KEYS[key] = packed_key
        parts.append(packed_key)
        if isinstance(value, np.ndarray):
            parts.extend(array_parts(value))
        elif isinstance(value, dict) and any(isinstance(v, np.ndarray) for v in value.values()):
            _write_map(value, pack, parts)
        else:
            parts.append(pack(value))  # arrays nested deeper still go through the ``default`` hook


def _map_header(size: int) -> bytes:
    if size < 16:
        return _FIXMAPS[size]
    packer = msgpack.Packer(autoreset=False)
    packer.pack_map_header(size)
    return packer.bytes()


_FIXMAPS = [bytes([0x80 | size]) for size in range(16)]


def decode(data: bytes | bytearray | memoryview, limits: Limits = DEFAULT_LIMITS) -> Message:
    """The message in ``data``, fully validated against ``limits``; raises only ProtocolError."""
    return _decode(data, limits, fast=True)


def _decode(data: bytes | bytearray | memoryview, limits: Limits, *, fast: bool) -> Message:
    """``decode``; ``fast=False`` skips :func:`protocols.fastpath.decode_transitions` (the general path,
    which decides every message the fast one does not accept, and which the tests compare it with)."""
    if not isinstance(data, bytes | bytearray | memoryview):
        raise ProtocolError("type", f"expected bytes, got {type(data).__name__}")
    size = len(data) if isinstance(data, bytes) else memoryview(data).nbytes
    if size > limits.max_message_bytes:
        raise ProtocolError("oversize", f"message of {size} bytes (limit {limits.max_message_bytes})")
    if fast:
        message = decode_transitions(data, limits)  # None unless a canonical, valid TransitionBatch
        if message is not None:
            return message
    try:
        envelope = msgpack.unpackb(
            data,
            ext_hook=ext_hook,
            raw=False,
            strict_map_key=True,
            max_str_len=4 * limits.max_string,
            max_array_len=limits.max_items,
            max_map_len=limits.max_items,
        )
    except ProtocolError:
        raise
    except ValueError as exc:
        reason = "oversize" if "exceeds max_" in str(exc) else "malformed"
        raise ProtocolError(reason, f"{type(exc).__name__}: {exc}") from None
    except Exception as exc:  # msgpack raises several types on garbage; all mean the same here
        raise ProtocolError("malformed", f"{type(exc).__name__}: {exc}") from None
    with quiet_float_errors():
        return _message_from_envelope(envelope, limits)


def _message_from_envelope(envelope: object, limits: Limits) -> Message:
    if not isinstance(envelope, dict) or envelope.keys() != _ENVELOPE_KEYS:
        raise ProtocolError("malformed", "not a navlearn envelope (a map with keys v, k, s, n, b)")
    kind = envelope["k"]
    cls = KINDS.get(kind) if isinstance(kind, str) else None
    if cls is None:
        raise ProtocolError("kind", f"unknown message kind {str(kind)[:40]!r}")
    version = envelope["v"]
    if type(version) is not int or version != cls.VERSION:
        raise ProtocolError("version", f"{kind} schema version {str(version)[:20]}, expected {cls.VERSION}")
    sender = check_string(envelope["s"], "envelope sender", limits, allow_empty=True)
    seq = check_int(envelope["n"], "envelope seq", 0)
    try:
        fields = cls.accept_body(envelope["b"], limits)
    except Exception:  # the fast path found something odd: the full checks say what
        fields = None
    if fields is not None:
        return _trusted(cls, fields, sender, seq)
    body = BodyReader(kind, envelope["b"], limits)
    try:
        fields = cls.read_body(body)
        body.finish()
    except ProtocolError:
        raise
    except Exception as exc:  # a schema check that tripped on an unexpected value: still the sender's fault
        raise ProtocolError("malformed", f"{kind} body: {type(exc).__name__}: {exc}") from None
    return _trusted(cls, fields, sender, seq)


def _trusted(cls: type[Message], fields: dict, sender: str, seq: int) -> Message:
    """The message from checked fields, skipping ``__init__``/``__post_init__`` (their conversions
    are no-ops on checked values, and a measurable share of decoding a transition batch)."""
    names = _FIELD_NAMES.get(cls)
    if names is None:
        names = _FIELD_NAMES[cls] = frozenset(f.name for f in dataclasses.fields(cls)) - {"sender", "seq"}
    if fields.keys() != names:
        raise AssertionError(f"{cls.__name__}.read_body returned {sorted(fields)}, not its fields")
    message = object.__new__(cls)
    message.__dict__.update(fields, sender=sender, seq=seq)
    return message

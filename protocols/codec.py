"""Bytes <-> messages: a msgpack envelope, numpy arrays as an extension type.

Envelope (a msgpack map)::

    {"v": schema version, "k": kind, "s": sender, "n": sequence number, "b": body map}

:func:`decode` trusts nothing: size, layout, kind, version and every body field
are checked, and any failure is a :class:`ProtocolError` with a reason code.
Nothing is ever unpickled.
"""

from __future__ import annotations

import dataclasses
import threading

import msgpack
import numpy as np

from protocols.arrays import array_parts, default, ext_hook
from protocols.checks import BodyReader, check_int, check_string
from protocols.errors import ProtocolError
from protocols.limits import DEFAULT_LIMITS, Limits
from protocols.messages import KINDS, Message

_ENVELOPE_KEYS = frozenset("vksnb")
_local = threading.local()
_FIELD_NAMES: dict[type, frozenset[str]] = {}


def _packer() -> msgpack.Packer:
    """This thread's packer. Reusing one buffer (autoreset off) avoids msgpack re-allocating and
    freeing its buffer for every large message, which costs ~10x the packing itself here."""
    packer = getattr(_local, "packer", None)
    if packer is None:
        packer = _local.packer = msgpack.Packer(default=default, use_bin_type=True, autoreset=False)
    return packer


def encode(message: Message) -> bytes:
    """The wire bytes of ``message`` (validated by the receiver, not here)."""
    if KINDS.get(type(message).KIND) is not type(message):
        raise ProtocolError("kind", f"{type(message).__name__} is not a registered message kind")
    packer = _packer()
    parts: list[bytes | memoryview] = []
    try:
        packer.pack_map_header(5)
        for key, value in (
            ("v", message.VERSION),
            ("k", message.KIND),
            ("s", message.sender),
            ("n", message.seq),
        ):
            packer.pack(key)
            packer.pack(value)
        packer.pack("b")
        _write_map(message.to_body(), packer, parts)
        parts.append(packer.bytes())
        return b"".join(parts)
    except ProtocolError:
        raise
    except (TypeError, ValueError, OverflowError) as exc:
        raise ProtocolError("type", f"cannot encode {message.KIND}: {exc}") from exc
    finally:
        packer.reset()


def _write_map(mapping: dict, packer: msgpack.Packer, parts: list[bytes | memoryview]) -> None:
    """Pack ``mapping``, splicing arrays (at this level or in maps of arrays) straight into ``parts``."""
    packer.pack_map_header(len(mapping))
    for key, value in mapping.items():
        packer.pack(key)
        if isinstance(value, np.ndarray):
            head, data = array_parts(value)
            parts.append(packer.bytes())
            packer.reset()
            parts.append(head)
            parts.append(data)
        elif isinstance(value, dict) and any(isinstance(v, np.ndarray) for v in value.values()):
            _write_map(value, packer, parts)
        else:
            packer.pack(value)  # arrays nested deeper still go through the ``default`` hook


def decode(data: bytes | bytearray | memoryview, limits: Limits = DEFAULT_LIMITS) -> Message:
    """The message in ``data``, fully validated against ``limits``; raises only ProtocolError."""
    if not isinstance(data, bytes | bytearray | memoryview):
        raise ProtocolError("type", f"expected bytes, got {type(data).__name__}")
    size = len(data) if isinstance(data, bytes) else memoryview(data).nbytes
    if size > limits.max_message_bytes:
        raise ProtocolError("oversize", f"message of {size} bytes (limit {limits.max_message_bytes})")
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

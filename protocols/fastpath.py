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
data is constant. The decoder compares those constant parts with byte templates cached per (N, D), reads
the strings and integers itself, makes the arrays, and applies every check of the schema's
``read_body`` and of the envelope; the encoder writes the same bytes as the general encoder from the
cached templates, without building the body map.

Both are derived from TransitionBatch's field declarations (protocols.schema): the layout above is
what the declarations say (texts and counts, then columns, each 1-d or 2-d with a named width), so
a field added there is read and written here too (tests/test_protocols_schema.py adds three). They
are generated as straight-line code once at import (``_TRANSITIONS.source`` shows it), as
``dataclasses`` generates ``__init__``: a loop over the fields costs about a fifth of a decode.

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
from protocols.messages import Message, TransitionBatch
from protocols.schema import Count, Schema, Text

_MAX_LAYOUTS = 256
"""Most (N, widths) layouts remembered (bounds memory whatever shapes arrive)."""
_EXT_HEAD = 6  # 0xc9, u32 payload length, type
_U32 = struct.Struct("<I")
_UINT_SIZES = {0xCC: 1, 0xCD: 2, 0xCE: 4, 0xCF: 8}
_STR_SIZES = {0xD9: 1, 0xDA: 2, 0xDB: 4}
_UNSIGNED = {np.dtype("<i8"): np.dtype("<u8"), np.dtype("<i4"): np.dtype("<u4")}


def _packed(*items: object) -> bytes:
    return b"".join(msgpack.packb(item) for item in items)


class _Format:
    """The byte layout of one table message kind, derived from its schema: texts and counts first
    (each a constant key and a value), then the columns (each a constant key and array header, and data).

    Its ``decode`` and ``encode`` are generated from the schema as straight-line Python (``source``
    holds their text), as ``dataclasses`` generates ``__init__``: a loop over the fields would cost
    the hot path about a fifth of its time.
    """

    def __init__(self, cls: type) -> None:
        schema: Schema = cls.SCHEMA
        names = [name for name, _ in schema.fields]
        columns = [name for name, _ in schema.columns]
        if not schema.table or names[len(names) - len(columns) :] != columns:
            raise TypeError(f"{cls.__name__}: the fast path needs texts and counts first, then only columns")
        self.scalars = tuple((name, spec) for name, spec in schema.fields if name not in columns)
        for name, spec in self.scalars:
            if not (isinstance(spec, Count) or spec == Text()):
                raise TypeError(f"{cls.__name__}.{name}: the fast path reads plain texts and counts only")
        packer = msgpack.Packer(autoreset=False)
        packer.pack_map_header(len(names))
        self.head = b"\x85" + _packed("v", cls.VERSION, "k", cls.KIND, "s")
        self.schema = schema
        self.columns = tuple(columns)
        self.specs = tuple(spec for _, spec in schema.columns)
        self.widths = tuple(schema.widths)
        self.layouts: dict[tuple[int, ...], _Layout] = {}
        namespace = {
            "CLS": cls,
            "HEAD": self.head,
            "HEAD_SIZE": len(self.head),
            "SEQ_KEY": _packed("n"),
            "BODY_START": _packed("b") + packer.bytes(),
            **{f"KEY_{name}": _packed(name) for name, _ in self.scalars},
            "NDARRAYS": (np.ndarray,) * len(columns),
            "DTYPES": tuple(spec.dtype for spec in self.specs),
            "LONGEST_KEY": max(map(len, (cls.KIND, *names))),
            "_layout": self.layout,
            "LAYOUTS": self.layouts,
            "INT64_MAX": INT64_MAX,
            "ProtocolError": ProtocolError,
            "_U32": _U32,
            "_str": _str,
            "_uint": _uint,
            "isfinite": isfinite,
            "ndarray": np.ndarray,
            "vdot": np.vdot,
        }
        self.source = self._decode_source(namespace) + "\n\n" + self._encode_source()
        exec(compile(self.source, f"<fastpath {cls.__name__}>", "exec"), namespace)
        self.decode: Callable[[bytes, Limits], Message | None] = namespace["decode"]
        self.encode: Callable[[Message, Callable[[object], bytes]], bytes | None] = namespace["encode"]

    def layout(self, n: int, *dims: int) -> _Layout:
        layout = self.layouts.get((n, *dims))
        if layout is None:
            layout = _Layout(self, n, dict(zip(self.widths, dims, strict=True)))
            if len(self.layouts) < _MAX_LAYOUTS:
                self.layouts[(n, *dims)] = layout
        return layout

    def _decode_source(self, namespace: dict) -> str:
        lines = [
            "def decode(data, limits):",
            "    max_string, max_bytes = limits.max_string, 4 * limits.max_string  # msgpack's max_str_len",
            f"    if limits.max_items < {len(self.scalars) + len(self.columns)} or max_bytes < LONGEST_KEY:",
            "        return None  # msgpack's limits bind keys and maps too",
            "    sender, at = _str(data, HEAD_SIZE, max_bytes)",
            "    if sender is None or len(sender) > max_string or not sender.isprintable():",
            "        return None",
            "    if not data.startswith(SEQ_KEY, at):",
            "        return None",
            f"    seq, at = _uint(data, at + {len(_packed('n'))})",
            "    if not 0 <= seq <= INT64_MAX or not data.startswith(BODY_START, at):",
            "        return None",
            f"    at += {len(namespace['BODY_START'])}",
        ]
        for name, spec in self.scalars:
            key = f"KEY_{name}"
            lines += [f"    if not data.startswith({key}, at):", "        return None"]
            if isinstance(spec, Text):
                lines += [
                    f"    f_{name}, at = _str(data, at + {len(_packed(name))}, max_bytes)",
                    f"    if f_{name} is None or not 0 < len(f_{name}) <= max_string"
                    f" or not f_{name}.isprintable():",
                ]
            else:
                lines += [
                    f"    f_{name}, at = _uint(data, at + {len(_packed(name))})",
                    f"    if not 0 <= f_{name} <= INT64_MAX:",
                ]
            lines.append("        return None")
        # The column section: N from the first column's header, each width from the first column of that
        # width, all then checked in full against the layout's templates.
        key_sizes = [len(_packed(name)) for name in self.columns]
        lines.append(f"    n = _U32.unpack_from(data, at + {key_sizes[0] + _EXT_HEAD + 4})[0]")
        fixed, rows, seen = 0, [], set()
        for key_size, spec in zip(key_sizes, self.specs, strict=True):
            if spec.width is not None and spec.width not in seen:
                seen.add(spec.width)
                offset = f"{fixed + key_size + _EXT_HEAD + 8}" + (
                    f" + n * ({' + '.join(rows)})" if rows else ""
                )
                lines.append(f"    w_{spec.width} = _U32.unpack_from(data, at + {offset})[0]")
            fixed += key_size + _EXT_HEAD + 8 * spec.ndim  # array headers: 8 bytes in 1-d, 16 in 2-d
            itemsize = spec.dtype.itemsize
            rows.append(str(itemsize) if spec.width is None else f"{itemsize} * w_{spec.width}")
        widths = "".join(f", w_{w}" for w in self.widths)
        tests = ["n > limits.max_batch", *(f"not 1 <= w_{w} <= limits.max_obs_dim" for w in self.widths)]
        tests.append(f"len(data) - at != {fixed} + n * ({' + '.join(rows)})")
        c = {name: f"c_{name}" for name in self.columns}
        lines += [
            f"    if {' or '.join(tests)}:",
            "        return None",
            f"    layout = LAYOUTS.get((n{widths},)) or _layout(n{widths})",
            "    for offset, template in layout.templates:",
            "        if not data.startswith(template, at + offset):",
            "            return None",
            "    for start, end, rest in layout.bool_spans:  # booleans only 0 or 1",
            "        if data[at + start : at + end].translate(None, b'\\x00\\x01') != rest:",
            "            return None",
            f"    {', '.join(c.values())}, = [",
            "        ndarray(shape, dtype, data[at + start : at + end]) if end"
            " else ndarray(shape, dtype, data, at + start)",
            "        for shape, dtype, start, end in layout.plans[at & 7]",
            "    ]",
        ]
        finite = [f"isfinite(vdot(c_{a}, c_{b}))" for a, b in self.schema.pairs]
        finite += [f"isfinite(vdot(c_{a}, c_{a}))" for a in self.schema.singles]
        if finite:
            lines += [f"    if not ({' and '.join(finite)}):", "        return None"]
        actions = self.schema.actions
        if actions:
            lines += [
                "    if n:",
                "        bound = INT64_MAX + 1 if limits.n_actions is None else limits.n_actions",
            ]
            for name in actions:  # negative actions wrap to >= 2**63 as unsigned
                lines += [f"        if c_{name}.item(c_{name}.argmax()) >= bound:", "            return None"]
                c[name] = f"c_{name}.view(DTYPES[{self.columns.index(name)}])"
        values = [f"{name}={value}" for name, value in c.items()]
        values += [f"{name}=f_{name}" for name, _ in self.scalars] + ["sender=sender", "seq=seq"]
        lines += [
            "    message = object.__new__(CLS)",
            f"    message.__dict__.update({', '.join(values)})",
            "    return message",
        ]
        return "\n".join(lines) + "\n"

    def _encode_source(self) -> str:
        c = [f"c_{name}" for name in self.columns]
        key = ", ".join(
            [f"{c[0]}.shape[0]", *(f"c_{names[0]}.shape[1]" for names in self.schema.widths.values())]
        )
        t = [f"t{i}" for i in range(len(c))]
        parts = ["HEAD", "pack(batch.sender)", "SEQ_KEY", "pack(batch.seq)", "BODY_START"]
        for name, _ in self.scalars:
            parts += [f"KEY_{name}", f"pack(batch.{name})"]
        for template, name in zip(t, c, strict=True):
            parts += [template, name]
        lines = [
            "def encode(batch, pack):",
            f"    {', '.join(c)}, = {', '.join(f'batch.{name}' for name in self.columns)},",
            f"    arrays = ({', '.join(c)},)",
            "    if tuple(map(type, arrays)) != NDARRAYS:",
            "        return None",
            "    try:",
            f"        key = ({key},)",
            "        layout = LAYOUTS.get(key) or _layout(*key)",
            "    except (IndexError, ProtocolError):  # a 0-d array, or a shape no header can hold",
            "        return None",
            f"    if ({', '.join(f'{x}.dtype' for x in c)},) != DTYPES"
            f" or ({', '.join(f'{x}.shape' for x in c)},) != layout.shapes:",
            "        return None",
            f"    {', '.join(t)}, = layout.parts",
            "    try:  # join takes an array's bytes only through a simple buffer (C-ordered arrays)",
            f"        return b''.join(({', '.join(parts)}))",
            "    except TypeError:",
            "        return None",
        ]
        return "\n".join(lines) + "\n"


class _Layout:
    """The constant parts of the column section for one N and widths, offsets from the first key."""

    __slots__ = ("bool_spans", "parts", "plans", "shapes", "size", "templates")

    def __init__(self, fmt: _Format, n: int, dims: dict[str, int]) -> None:
        templates, arrays, at = [], [], 0
        for name, spec in zip(fmt.columns, fmt.specs, strict=True):
            shape = (n,) if spec.width is None else (n, dims[spec.width])
            template = _packed(name) + _array_head(spec.dtype, shape)
            templates.append((at, template))
            at += len(template)
            view = _UNSIGNED[spec.dtype] if spec.actions else spec.dtype
            nbytes = math.prod(shape) * spec.dtype.itemsize
            arrays.append((shape, view, at, at + nbytes, spec.dtype.alignment > 1))
            at += nbytes
        spans: list[tuple[int, int, bytes]] = []  # runs of consecutive boolean columns
        for i, spec in enumerate(fmt.specs):
            if spec.dtype.kind != "b":
                continue
            start, end = arrays[i][2:4]
            if spans and fmt.specs[i - 1].dtype.kind == "b":
                start, _, rest = spans.pop()
                spans.append((start, end, rest + templates[i][1].translate(None, b"\x00\x01")))
            else:
                spans.append((start, end, b""))
        self.size = at
        self.templates = tuple(templates)
        """(offset, the column's key and its extension and array headers), in wire order."""
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
        self.bool_spans = tuple(spans)
        """Runs of boolean columns: (start, end, what deleting every 0 and 1 byte there must leave)."""


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


_TRANSITIONS = _Format(TransitionBatch)


def decode_transitions(data: bytes, limits: Limits) -> TransitionBatch | None:
    """The TransitionBatch in ``data`` if it is in the canonical layout and passes every check the general
    decoder applies (``limits.max_message_bytes`` excepted: the caller checks it first); else None."""
    if type(data) is not bytes or not data.startswith(_TRANSITIONS.head):
        return None
    try:
        return _TRANSITIONS.decode(data, limits)
    except Exception:  # any surprise means "not the canonical layout": the general path says what
        return None


def encode_transitions(batch: TransitionBatch, pack: Callable[[object], bytes]) -> bytes | None:
    """The general encoder's bytes for ``batch`` (``pack`` packs one value, as it does there), written
    from cached templates; None if an array is not a numpy array of its wire dtype, shape and C order
    (the general encoder then handles it, or raises)."""
    return _TRANSITIONS.encode(batch, pack)

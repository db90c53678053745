"""numpy arrays as a msgpack extension type.

Payload layout of extension :data:`ARRAY_EXT_CODE` (header little-endian)::

    u8 dtype code | u8 ndim | 2 zero bytes | ndim x u32 shape | zero padding to 8 bytes | raw data

The data is the array's bytes in C order, little-endian. The header is padded
to a multiple of 8 bytes so decoded arrays are aligned, and decoding is
zero-copy: the array is a view (``np.ndarray(buffer=...)``) of the bytes msgpack
hands to the extension hook, so decoded arrays are read-only.
"""

from __future__ import annotations

import math
import struct

import msgpack
import numpy as np

from protocols.errors import ProtocolError

ARRAY_EXT_CODE = 1
MAX_WIRE_NDIM = 32

_DTYPE_BY_CODE: dict[int, np.dtype] = {
    1: np.dtype("|b1"),
    2: np.dtype("|u1"),
    3: np.dtype("|i1"),
    4: np.dtype("<u2"),
    5: np.dtype("<i2"),
    6: np.dtype("<u4"),
    7: np.dtype("<i4"),
    8: np.dtype("<u8"),
    9: np.dtype("<i8"),
    10: np.dtype("<f2"),
    11: np.dtype("<f4"),
    12: np.dtype("<f8"),
}
_CODE_BY_DTYPE: dict[np.dtype, int] = {dt: code for code, dt in _DTYPE_BY_CODE.items()}
_BOOL_CODE = 1
_HEADERS = [struct.Struct(f"<BBxx{ndim}I{(-(4 + 4 * ndim)) % 8}x") for ndim in range(MAX_WIRE_NDIM + 1)]
_HEADER_SIZES = tuple(h.size for h in _HEADERS) + (0,) * (256 - len(_HEADERS))  # by the ndim byte
_EXT32 = struct.Struct(">BIb")  # msgpack "ext 32": 0xc9, payload length, type
_CACHE_SIZE = 1024
"""Most distinct array layouts remembered by the encoder and the decoder (bounds their memory)."""
_HEADS: dict[tuple[np.dtype, tuple[int, ...]], bytes] = {}
_LAYOUTS: dict[bytes, tuple[tuple[int, ...], np.dtype, int, bool]] = {}


def array_parts(array: np.ndarray) -> tuple[bytes, memoryview]:
    """``array`` as a complete msgpack extension, in two parts: (ext header + array header, raw data).

    The encoder splices both into its output, so the array's bytes are copied once. Headers are
    cached per (dtype, shape): a batch of the usual size costs a dictionary look-up, not two packs.
    """
    key = (array.dtype, array.shape)
    head = _HEADS.get(key)
    if head is None:
        if array.dtype not in _CODE_BY_DTYPE and array.dtype.str.startswith(">"):
            return array_parts(array.astype(array.dtype.newbyteorder("<")))
        head = _array_head(array.dtype, array.shape)
        if len(_HEADS) < _CACHE_SIZE:
            _HEADS[key] = head
    if not array.flags.c_contiguous:
        array = np.ascontiguousarray(array)
    return head, array.data


def _array_head(dtype: np.dtype, shape: tuple[int, ...]) -> bytes:
    code = _CODE_BY_DTYPE.get(dtype)
    if code is None:
        raise ProtocolError("dtype", f"cannot send arrays of dtype {dtype}")
    ndim = len(shape)
    if ndim > MAX_WIRE_NDIM:
        raise ProtocolError("shape", f"cannot send an array with {ndim} dimensions")
    header = _HEADERS[ndim]
    try:
        return _EXT32.pack(0xC9, header.size + math.prod(shape) * dtype.itemsize, ARRAY_EXT_CODE) + (
            header.pack(code, ndim, *shape)
        )
    except struct.error:
        raise ProtocolError("shape", f"cannot send an array of shape {shape}") from None


def pack_array(array: np.ndarray) -> msgpack.ExtType:
    """The extension value for ``array`` (used for arrays nested where the encoder does not splice)."""
    head, data = array_parts(array)
    return msgpack.ExtType(ARRAY_EXT_CODE, head[_EXT32.size :] + bytes(data))


def unpack_array(payload: bytes) -> np.ndarray:
    """Inverse of :func:`pack_array`; raises :class:`ProtocolError` on any inconsistency.

    Fast path: a header seen before (same dtype and shape) is looked up whole in a bounded cache
    of layouts that passed the full checks of :func:`_array_layout`.
    """
    size = len(payload)
    if size >= 4:
        header_size = _HEADER_SIZES[payload[1]]
        layout = _LAYOUTS.get(payload[:header_size])
        if layout is not None:
            shape, dtype, nbytes, boolean = layout
            if size - header_size == nbytes and not (
                boolean and payload[header_size:].translate(None, b"\x00\x01")
            ):
                return np.ndarray(shape, dtype, payload, header_size)
    shape, dtype, nbytes, boolean = _array_layout(payload)
    header_size = size - nbytes
    if boolean and payload[header_size:].translate(None, b"\x00\x01"):
        raise ProtocolError("malformed", "boolean array holds bytes other than 0 and 1")
    if len(_LAYOUTS) < _CACHE_SIZE:
        _LAYOUTS[bytes(payload[:header_size])] = (shape, dtype, nbytes, boolean)
    return np.ndarray(shape, dtype, payload, header_size)


def _array_layout(payload: bytes) -> tuple[tuple[int, ...], np.dtype, int, bool]:
    """(shape, dtype, data bytes, is boolean) of an array extension, every header field checked."""
    size = len(payload)
    if size < 4:
        raise ProtocolError("malformed", f"array extension of {size} bytes is too short")
    code, ndim = payload[0], payload[1]
    dtype = _DTYPE_BY_CODE.get(code)
    if dtype is None:
        raise ProtocolError("dtype", f"unknown array dtype code {code}")
    if ndim > MAX_WIRE_NDIM:
        raise ProtocolError("shape", f"array with {ndim} dimensions")
    header = _HEADERS[ndim]
    if size < header.size:
        raise ProtocolError("malformed", "array extension shorter than its header")
    shape = header.unpack_from(payload)[2:]
    nbytes = math.prod(shape) * dtype.itemsize
    if nbytes != size - header.size:
        got = size - header.size
        raise ProtocolError(
            "shape", f"array of shape {shape} and dtype {dtype} needs {nbytes} bytes, got {got}"
        )
    return shape, dtype, nbytes, code == _BOOL_CODE


def ext_hook(code: int, payload: bytes) -> np.ndarray:
    """msgpack ``ext_hook``: only the array extension exists on the wire."""
    if code != ARRAY_EXT_CODE:
        raise ProtocolError("malformed", f"unknown msgpack extension type {code}")
    return unpack_array(payload)


def default(obj: object) -> object:
    """msgpack ``default`` hook: arrays become the extension, numpy scalars plain numbers."""
    if isinstance(obj, np.ndarray):
        return pack_array(obj)
    if isinstance(obj, np.generic):
        return obj.item()
    raise ProtocolError("type", f"cannot encode a value of type {type(obj).__name__}")

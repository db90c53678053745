"""Validation helpers used by the message schemas: every check raises ProtocolError."""

from __future__ import annotations

import math
from collections.abc import Collection
from typing import Any

import numpy as np

from protocols.errors import ProtocolError
from protocols.limits import Limits

INT64_MAX = 2**63 - 1
INT64_MIN = -(2**63)
FLOAT_DTYPES = frozenset(np.dtype(s) for s in ("<f2", "<f4", "<f8"))
INT_DTYPES = frozenset(np.dtype(s) for s in ("|u1", "|i1", "<u2", "<i2", "<u4", "<i4", "<u8", "<i8"))
TENSOR_DTYPES = FLOAT_DTYPES | INT_DTYPES | {np.dtype("|b1")}
_MISSING = object()
_UNSIGNED = {dt: np.dtype(dt.str.replace("i", "u")) for dt in INT_DTYPES}

JSONLike = None | bool | int | float | str | list["JSONLike"] | dict[str, "JSONLike"]


def check_string(value: object, what: str, limits: Limits, *, allow_empty: bool = False) -> str:
    if not isinstance(value, str):
        raise ProtocolError("type", f"{what} must be a string, got {type(value).__name__}")
    if len(value) > limits.max_string:
        raise ProtocolError("string", f"{what} has {len(value)} characters (limit {limits.max_string})")
    if not value and not allow_empty:
        raise ProtocolError("string", f"{what} is empty")
    if not value.isprintable():
        raise ProtocolError("string", f"{what} contains control characters")
    return value


def check_int(value: object, what: str, lo: int = INT64_MIN, hi: int = INT64_MAX) -> int:
    if type(value) is not int:
        raise ProtocolError("type", f"{what} must be an integer, got {type(value).__name__}")
    if not lo <= value <= hi:
        raise ProtocolError("range", f"{what} = {value} is outside [{lo}, {hi}]")
    return value


def check_float(value: object, what: str, *, finite: bool = True) -> float:
    if type(value) not in (int, float):
        raise ProtocolError("type", f"{what} must be a number, got {type(value).__name__}")
    if finite and not math.isfinite(value):
        raise ProtocolError("nonfinite", f"{what} = {value} is not finite")
    return float(value)


def check_json(value: object, what: str, limits: Limits, depth: int = 0) -> JSONLike:
    """A JSON-like value: None, bool, int, finite float, bounded str, list or str-keyed map of these."""
    if depth > limits.max_depth:
        raise ProtocolError("oversize", f"{what} is nested deeper than {limits.max_depth}")
    if value is None or type(value) is bool:
        return value
    if type(value) is int:
        return check_int(value, what)
    if type(value) is float:
        return check_float(value, what)
    if isinstance(value, str):
        return check_string(value, what, limits, allow_empty=True)
    if isinstance(value, list):
        check_size(value, what, limits)
        return [check_json(v, f"{what}[{i}]", limits, depth + 1) for i, v in enumerate(value)]
    if isinstance(value, dict):
        check_size(value, what, limits)
        for key, v in value.items():
            check_string(key, f"{what} key", limits, allow_empty=True)
            check_json(v, f"{what}.{key}", limits, depth + 1)
        return value
    raise ProtocolError("type", f"{what} holds a {type(value).__name__}, not a JSON-like value")


def check_size(collection: Collection, what: str, limits: Limits) -> None:
    if len(collection) > limits.max_items:
        raise ProtocolError("oversize", f"{what} has {len(collection)} entries (limit {limits.max_items})")


class BodyReader:
    """Reads the fields of one message body, checking each; :meth:`finish` rejects unknown fields."""

    def __init__(self, kind: str, body: object, limits: Limits) -> None:
        if not isinstance(body, dict):
            raise ProtocolError("type", f"the {kind} body must be a map, got {type(body).__name__}")
        self.kind = kind
        self.body = body
        self.limits = limits
        self._read: set[str] = set()

    def what(self, name: str) -> str:
        return f"{self.kind}.{name}"

    def raw(self, name: str) -> Any:
        if name not in self.body:
            raise ProtocolError("field", f"{self.what(name)} is missing")
        self._read.add(name)  # so ``_read`` only holds names of the body (see finish)
        return self.body[name]

    def string(
        self, name: str, *, allow_empty: bool = False, optional: bool = False, choices: Collection[str] = ()
    ) -> str | None:
        value = self.raw(name)
        if optional and value is None:
            return None
        value = check_string(value, self.what(name), self.limits, allow_empty=allow_empty)
        if choices and value not in choices:
            raise ProtocolError("string", f"{self.what(name)} = {value!r} is not one of {sorted(choices)}")
        return value

    def integer(self, name: str, lo: int = 0, hi: int = INT64_MAX) -> int:
        return check_int(self.raw(name), self.what(name), lo, hi)

    def array(self, name: str, dtypes: Collection[np.dtype], ndim: int, *, finite: bool = True) -> np.ndarray:
        """An array field with one of ``dtypes`` and ``ndim`` dimensions, at most ``max_batch`` rows."""
        value = self.raw(name)
        try:
            return check_array(value, name, self.limits, dtypes, ndim, finite=finite)
        except ProtocolError as exc:  # name the field in full only when it failed
            raise ProtocolError(exc.reason, f"{self.kind}.{exc.message}") from None

    def arrays(
        self, schema: dict[str, tuple[Collection[np.dtype], int]], finite_later: Collection[str] = ()
    ) -> dict[str, np.ndarray]:
        """Several array fields at once, ``schema`` mapping name -> (dtypes, ndim); the hot path.

        The checks are those of :func:`check_array`, inlined; a field that fails any of them goes
        through :func:`check_array` again for its precise error. Float fields named in
        ``finite_later`` skip the finite check: the caller must check them itself (e.g. two at once
        with :func:`check_finite_pair`).
        """
        body, max_batch, out = self.body, self.limits.max_batch, {}
        for name, (dtypes, ndim) in schema.items():
            value = body.get(name, _MISSING)
            if (
                type(value) is not np.ndarray
                or value.dtype not in dtypes
                or value.ndim != ndim
                or (ndim and value.shape[0] > max_batch)
                or (value.dtype.kind == "f" and name not in finite_later and not all_finite(value))
            ):
                if value is _MISSING:
                    raise ProtocolError("field", f"{self.kind}.{name} is missing")
                try:
                    check_array(value, name, self.limits, dtypes, ndim)
                except ProtocolError as exc:
                    raise ProtocolError(exc.reason, f"{self.kind}.{exc.message}") from None
            out[name] = value
        self._read.update(schema)
        return out

    def json_map(self, name: str, *, optional: bool = False) -> dict | None:
        value = self.raw(name)
        if optional and value is None:
            return None
        if not isinstance(value, dict):
            raise ProtocolError("type", f"{self.what(name)} must be a map, got {type(value).__name__}")
        return check_json(value, self.what(name), self.limits)

    def number_map(self, name: str, number: type, *, finite: bool = True) -> dict[str, int | float]:
        """A flat map from strings to ints (``number=int``) or floats."""
        value = self.raw(name)
        if not isinstance(value, dict):
            raise ProtocolError("type", f"{self.what(name)} must be a map, got {type(value).__name__}")
        check_size(value, self.what(name), self.limits)
        out: dict[str, int | float] = {}
        for key, v in value.items():
            what = f"{self.what(name)}[{key!r}]"
            check_string(key, f"{self.what(name)} key", self.limits)
            out[key] = check_int(v, what) if number is int else check_float(v, what, finite=finite)
        return out

    def list(self, name: str) -> list:
        value = self.raw(name)
        if not isinstance(value, list):
            raise ProtocolError("type", f"{self.what(name)} must be a list, got {type(value).__name__}")
        check_size(value, self.what(name), self.limits)
        return value

    def finish(self) -> None:
        if len(self.body) == len(self._read):  # ``_read`` is a subset of the body's keys
            return
        unknown = self.body.keys() - self._read
        if unknown:
            raise ProtocolError("field", f"unexpected {self.kind} fields {sorted(map(str, unknown))}")


def check_array(
    value: object, what: str, limits: Limits, dtypes: Collection[np.dtype], ndim: int, *, finite: bool = True
) -> np.ndarray:
    """``value`` if it is an array with one of ``dtypes``, ``ndim`` dimensions, at most ``max_batch``
    rows and (``finite``, float dtypes) no NaN or infinity."""
    if type(value) is not np.ndarray:
        raise ProtocolError("type", f"{what} must be an array, got {type(value).__name__}")
    if value.dtype not in dtypes:
        allowed = sorted(str(d) for d in dtypes)
        raise ProtocolError("dtype", f"{what} has dtype {value.dtype}, expected one of {allowed}")
    if value.ndim != ndim:
        raise ProtocolError("shape", f"{what} has shape {value.shape}, expected {ndim} dimensions")
    if ndim and value.shape[0] > limits.max_batch:
        raise ProtocolError("oversize", f"{what} has {value.shape[0]} rows (limit {limits.max_batch})")
    if finite and value.dtype.kind == "f" and not all_finite(value):
        bad = value.size - np.count_nonzero(np.isfinite(value))
        raise ProtocolError("nonfinite", f"{what} holds {bad} NaN or infinite values")
    return value


def all_finite(values: np.ndarray, other: np.ndarray | None = None) -> bool:
    """Whether float array ``values`` (and ``other``, if given) hold no NaN and no infinity.

    Fast path, one BLAS pass and no temporary array: a dot product is finite only if every term is,
    and a term ``x * y`` is finite only if both ``x`` and ``y`` are (``inf * 0`` is NaN, NaN
    propagates, ``inf - inf`` is NaN). So ``values . values`` (or ``values . other``, same size)
    being finite proves every element finite. The converse fails only when finite terms
    overflow (elements beyond ~1e19 in float32): then the exact elementwise check decides.

    numpy warns about the overflow or NaN it meets on the fast path; :func:`protocols.codec.decode`
    runs every check under ``quiet_float_errors()``, other callers should too.
    """
    if other is None:
        other = values
    if values.size == other.size and math.isfinite(np.vdot(values, other)):  # vdot flattens both
        return True
    return bool(np.isfinite(values).all()) and (other is values or bool(np.isfinite(other).all()))


def quiet_float_errors() -> np.errstate:
    """Context in which :func:`all_finite` meets NaN and overflow silently (they are expected input)."""
    return np.errstate(over="ignore", invalid="ignore")


def check_finite_pair(what: str, first: tuple[str, np.ndarray], second: tuple[str, np.ndarray]) -> None:
    """Both (name, float array) hold only finite values; one pass when they have the same size."""
    if not all_finite(first[1], second[1]):
        for name, values in (first, second):
            if not all_finite(values):
                bad = values.size - np.count_nonzero(np.isfinite(values))
                raise ProtocolError("nonfinite", f"{what}.{name} holds {bad} NaN or infinite values")


def actions_in_range(actions: np.ndarray, limits: Limits) -> bool:
    """Integer ``actions`` lie in [0, n_actions) (only >= 0 when n_actions is None)."""
    if not actions.size:
        return True
    if limits.n_actions is None:
        return bool(actions.min() >= 0)
    return bool(actions.view(_UNSIGNED[actions.dtype]).max() < limits.n_actions)  # negatives wrap


def check_actions(actions: np.ndarray, what: str, limits: Limits) -> None:
    """Integer ``actions`` lie in [0, n_actions) (only >= 0 when n_actions is None)."""
    if not actions_in_range(actions, limits):
        bound = "inf" if limits.n_actions is None else limits.n_actions
        raise ProtocolError(
            "action_range", f"{what} spans [{actions.min()}, {actions.max()}], outside [0, {bound})"
        )


def check_rows(what: str, expected: int, *arrays: tuple[str, np.ndarray]) -> None:
    """All ``arrays`` (name, array) have ``expected`` rows."""
    for name, array in arrays:
        if array.shape[0] != expected:
            raise ProtocolError("shape", f"{what}: {name} has {array.shape[0]} rows, expected {expected}")

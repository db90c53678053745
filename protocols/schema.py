"""Field declarations for the message dataclasses, and the checks derived from them.

A message class (``protocols.messages``) declares each body field with one of the functions below::

    actor: str = text()                               # a non-empty printable string
    policy_version: int = count()                     # an integer in [0, 2**63)
    obs: np.ndarray = column("<f4", width="obs_dim")  # float32 (N, obs_dim)
    action: np.ndarray = column("<i8", actions=True)  # int64 (N,), each in [0, n_actions)

That line is everything the wire needs to know about the field. :func:`schema_of` collects a class's
declarations, in field order (the order of the body map on the wire), into a :class:`Schema`, from
which are derived:

- construction: arrays converted to their wire dtype (``Message.__post_init__``);
- the body map the encoder writes (``Message.to_body``, field order);
- the full checks with their error messages (``Message.read_body`` with :class:`BodyReader`,
  :func:`check_columns`), and the one-conjunction check of the general decode path (:func:`accept`);
- the TransitionBatch fast path (``protocols.fastpath``: templates, parser and encoder).

Columns are the arrays of a *table* message: one row per item (transition), all with the same number of
rows. A column is 1-d, or 2-d with a named width (``obs_dim``): columns of one width have equal shapes,
and each width lies in [1, ``Limits.max_obs_dim``]. Float columns of one width are checked finite in
pairs (one dot product for two arrays), ``actions=True`` columns lie in [0, ``Limits.n_actions``).
Arrays that are not columns (``array``) are checked alone; the message's ``check_body`` relates them.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from protocols.checks import (
    INT64_MAX,
    BodyReader,
    actions_in_range,
    all_finite,
    check_actions,
    check_finite_pair,
    check_rows,
)
from protocols.errors import ProtocolError
from protocols.limits import Limits

SPEC = "navlearn.wire"
"""The ``dataclasses.field`` metadata key holding a field's wire declaration."""


@dataclass(frozen=True)
class Text:
    """A printable string of at most ``Limits.max_string`` characters."""

    allow_empty: bool = False
    optional: bool = False
    """None is allowed too."""
    choices: tuple[str, ...] = ()
    """If given, the only values allowed."""

    def read(self, body: BodyReader, name: str) -> str | None:
        return body.string(name, allow_empty=self.allow_empty, optional=self.optional, choices=self.choices)

    def accepts(self, value: object, limits: Limits) -> bool:
        if value is None:
            return self.optional
        return (
            type(value) is str
            and (self.allow_empty or len(value) > 0)
            and len(value) <= limits.max_string
            and value.isprintable()
            and (not self.choices or value in self.choices)
        )


@dataclass(frozen=True)
class Count:
    """An integer in [0, 2**63)."""

    def read(self, body: BodyReader, name: str) -> int:
        return body.integer(name)

    def accepts(self, value: object, limits: Limits) -> bool:
        return type(value) is int and 0 <= value <= INT64_MAX


@dataclass(frozen=True)
class Array:
    """A numpy array of one wire dtype; a column of the message's table if ``column``."""

    dtype: np.dtype
    ndim: int
    column: bool = False
    width: str | None = None
    """A column's named second dimension (None: a 1-d column)."""
    actions: bool = False
    """Integer actions, each in [0, Limits.n_actions)."""


@dataclass(frozen=True)
class JsonMap:
    """A map of JSON-like values (finite floats, bounded strings and nesting)."""

    optional: bool = False

    def read(self, body: BodyReader, name: str) -> dict | None:
        return body.json_map(name, optional=self.optional)


@dataclass(frozen=True)
class NumberMap:
    """A flat map from strings to ints or floats (finite unless ``finite=False``)."""

    number: type
    finite: bool = True

    def read(self, body: BodyReader, name: str) -> dict:
        return body.number_map(name, self.number, finite=self.finite)


@dataclass(frozen=True)
class Custom:
    """A field with its own reader, and writer if its value is not already a wire value."""

    reader: Callable[[BodyReader, str], Any]
    writer: Callable[[Any], Any] | None = None

    def read(self, body: BodyReader, name: str) -> Any:
        return self.reader(body, name)


@dataclass(frozen=True)
class Inside:
    """A field carried on the wire as the entry ``key`` of the map field ``container`` (None: absent),
    so that a typed field can join a message without changing its bytes."""

    container: str
    key: str
    reader: Callable[[object, str, Limits], Any]
    """(the entry, its name for errors, limits) -> the field's value; raises ProtocolError."""
    writer: Callable[[Any], Any]


Spec = Text | Count | Array | JsonMap | NumberMap | Custom | Inside


def _declare(spec: Spec, **options: Any) -> Any:
    return field(metadata={SPEC: spec}, **options)


def text(
    *, allow_empty: bool = False, optional: bool = False, choices: Collection[str] = (), **options
) -> Any:
    """A printable string (non-empty unless ``allow_empty``; None allowed if ``optional``)."""
    return _declare(Text(allow_empty, optional, tuple(choices)), **options)


def count(**options: Any) -> Any:
    """An integer in [0, 2**63)."""
    return _declare(Count(), **options)


def column(dtype: str, *, width: str | None = None, actions: bool = False) -> Any:
    """A column of the message's table: ``dtype`` (N,), or (N, <width>) if ``width`` names one."""
    return _declare(Array(np.dtype(dtype), 1 if width is None else 2, True, width, actions))


def array(dtype: str, ndim: int, *, actions: bool = False) -> Any:
    """An array of ``dtype`` with ``ndim`` dimensions, checked alone (the message relates it to others)."""
    return _declare(Array(np.dtype(dtype), ndim, actions=actions))


def json_map(*, optional: bool = False, **options: Any) -> Any:
    """A map of JSON-like values (None allowed if ``optional``)."""
    return _declare(JsonMap(optional), **options)


def number_map(number: type, *, finite: bool = True, **options: Any) -> Any:
    """A flat map from strings to ``number`` (int or float; floats finite unless ``finite=False``)."""
    return _declare(NumberMap(number, finite), **options)


def inside(container: str, key: str, reader: Callable, writer: Callable, **options: Any) -> Any:
    """A typed field carried as the entry ``key`` of map field ``container`` (:class:`Inside`)."""
    return _declare(Inside(container, key, reader, writer), **options)


def custom(reader: Callable[[BodyReader, str], Any], writer: Callable | None = None, **options: Any) -> Any:
    """A field read by ``reader(body, name)`` and written as ``writer(value)`` (as it is if None)."""
    return _declare(Custom(reader, writer), **options)


@dataclass(frozen=True)
class Schema:
    """A message class's wire declarations, and what the codec and the checks derive from them."""

    kind: str
    fields: tuple[tuple[str, Spec], ...]
    """(name, declaration) of every body field, in wire order."""
    nested: tuple[tuple[str, Inside], ...]
    """Fields carried inside a map field (:class:`Inside`)."""
    arrays: dict[str, tuple[frozenset[np.dtype], int]]
    """Array fields: name -> (allowed dtypes, ndim), as :meth:`BodyReader.arrays` takes them."""
    dtypes: dict[str, np.dtype]
    """Array fields: name -> wire dtype (constructors convert to it)."""
    others: tuple[tuple[str, Spec], ...]
    """The fields that are not arrays, read one by one after the arrays."""
    columns: tuple[tuple[str, Array], ...]
    widths: dict[str, tuple[str, ...]]
    """Width name -> the columns of that width, in order (the first one is the reference)."""
    pairs: tuple[tuple[str, str], ...]
    """Float columns checked finite two at a time (same width, consecutive)."""
    singles: tuple[str, ...]
    """Float columns checked finite alone."""
    actions: tuple[str, ...]
    writers: dict[str, Callable[[Any], Any]]
    table: bool
    """Only columns, texts and counts: :func:`accept` applies (and protocols.fastpath may)."""

    @property
    def rows_from(self) -> str:
        """The column whose rows the others must match (the first 2-d one, else the first)."""
        return next(iter(self.widths.values()))[0] if self.widths else self.columns[0][0]


def schema_of(cls: type, kind: str) -> Schema:
    """The :class:`Schema` of a message dataclass (every field but ``sender`` and ``seq`` declared)."""
    declared = []
    for f in fields(cls):
        if f.name in ("sender", "seq"):
            continue
        if SPEC not in f.metadata:
            raise TypeError(
                f"{cls.__name__}.{f.name} has no wire declaration (use protocols.schema.text(), ...)"
            )
        declared.append((f.name, f.metadata[SPEC]))
    nested = tuple((name, s) for name, s in declared if isinstance(s, Inside))
    declared = [(name, s) for name, s in declared if not isinstance(s, Inside)]
    arrays = {name: s for name, s in declared if isinstance(s, Array)}
    columns = tuple((name, s) for name, s in arrays.items() if s.column)
    widths: dict[str, list[str]] = {}
    for name, s in columns:
        if s.width is not None:
            widths.setdefault(s.width, []).append(name)
    pairs, singles = [], []
    for name, s in columns:
        if s.dtype.kind != "f":
            continue
        same = widths.get(s.width, [name]) if s.width else [name]
        floats = [n for n in same if arrays[n].dtype.kind == "f"]
        i = floats.index(name)
        if i % 2 == 0 and i + 1 < len(floats):
            pairs.append((name, floats[i + 1]))
        elif i % 2 == 0:
            singles.append(name)
    return Schema(
        kind=kind,
        fields=tuple(declared),
        nested=nested,
        arrays={name: (frozenset({s.dtype}), s.ndim) for name, s in arrays.items()},
        dtypes={name: s.dtype for name, s in arrays.items()},
        others=tuple((name, s) for name, s in declared if not isinstance(s, Array)),
        columns=columns,
        widths={w: tuple(names) for w, names in widths.items()},
        pairs=tuple(pairs),
        singles=tuple(singles),
        actions=tuple(name for name, s in arrays.items() if s.actions),
        writers={name: s.writer for name, s in declared if isinstance(s, Custom) and s.writer is not None},
        table=bool(columns)
        and len(columns) == len(arrays)
        and all(isinstance(s, Text | Count) for name, s in declared if name not in arrays),
    )


def read(
    schema: Schema, body: BodyReader, check: Callable[[dict, Limits], None] | None = None
) -> dict[str, Any]:
    """Every field of ``body`` checked by its declaration, then the columns related
    (:func:`check_columns`), then ``check`` (the message's own relations between fields), then the
    actions of arrays that are not columns."""
    later = {name for pair in schema.pairs for name in pair}
    out: dict[str, Any] = body.arrays(schema.arrays, finite_later=later) if schema.arrays else {}
    for name, spec in schema.others:
        out[name] = spec.read(body, name)
    for name, spec in schema.nested:
        container = out[spec.container]
        value = None if container is None else container.pop(spec.key, None)
        what = f"{schema.kind}.{spec.container}.{spec.key}"
        out[name] = None if value is None else spec.reader(value, what, body.limits)
    if schema.columns:
        check_columns(schema, out, body.limits)
    if check is not None:
        check(out, body.limits)
    columns = dict(schema.columns)
    for name in schema.actions:
        if name not in columns:
            check_actions(out[name], f"{schema.kind}.{name}", body.limits)
    return out


def check_columns(schema: Schema, out: dict[str, Any], limits: Limits) -> None:
    """The columns' widths, shapes, finite floats, rows and actions (each column read on its own)."""
    kind = schema.kind
    for names in schema.widths.values():
        first = out[names[0]]
        if not 1 <= first.shape[1] <= limits.max_obs_dim:
            raise ProtocolError(
                "shape",
                f"{kind}.{names[0]} has dimension {first.shape[1]} (accepted: 1 to {limits.max_obs_dim})",
            )
        for name in names[1:]:
            if out[name].shape != first.shape:
                raise ProtocolError(
                    "shape", f"{kind}: {name} {out[name].shape} differs from {names[0]} {first.shape}"
                )
    for a, b in schema.pairs:
        check_finite_pair(kind, (a, out[a]), (b, out[b]))
    n = out[schema.rows_from].shape[0]
    for name, _ in schema.columns:
        if out[name].shape[0] != n:
            check_rows(kind, n, (name, out[name]))
    for name, spec in schema.columns:
        if spec.actions:
            check_actions(out[name], f"{kind}.{name}", limits)


def accept(schema: Schema, body: object, limits: Limits) -> dict[str, Any] | None:
    """What :func:`read` returns for ``body`` if it passes all of its checks, else None; for table
    messages (columns and text/count fields), every check as one pass without the per-field machinery.
    Never accepts what :func:`read` rejects."""
    if type(body) is not dict or len(body) != len(schema.fields):  # no unknown fields
        return None
    get, ndarray, out, n, widths = body.get, np.ndarray, {}, -1, {}
    for name, spec in schema.columns:
        value = get(name)
        if type(value) is not ndarray or value.dtype != spec.dtype or value.ndim != spec.ndim:
            return None
        if spec.width is not None and widths.setdefault(spec.width, value.shape[1]) != value.shape[1]:
            return None
        if n != value.shape[0] and n >= 0:
            return None
        n = value.shape[0]
        out[name] = value
    if n > limits.max_batch or not all(1 <= d <= limits.max_obs_dim for d in widths.values()):
        return None
    for name, spec in schema.others:
        value = get(name)
        if not spec.accepts(value, limits):
            return None
        out[name] = value
    for a, b in schema.pairs:
        if not all_finite(out[a], out[b]):
            return None
    for name in schema.singles:
        if not all_finite(out[name]):
            return None
    for name in schema.actions:
        if not actions_in_range(out[name], limits):
            return None
    return out

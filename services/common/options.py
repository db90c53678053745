"""Flags and environment variables from one flat, documented config dataclass.

Every service keeps its settings in a dataclass whose fields carry a one-line
docstring (cleanrl style). :func:`add_options` turns the fields into ``--flags``
(the docstring is the help text) that also read ``<PREFIX>_<FIELD>`` environment
variables; :func:`options_from_args` resolves flag > environment > default.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import functools
import inspect
import itertools
import os
import textwrap
import typing
from typing import Any, TypeVar

T = TypeVar("T")


class OptionError(ValueError):
    """A flag or environment variable holds a value its field cannot take."""


@functools.cache
def field_docs(cls: type) -> dict[str, str]:
    """Field name -> the docstring written under it in the class body (first line of each)."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass):
            continue
        body = ast.parse(textwrap.dedent(inspect.getsource(klass))).body[0].body
        for node, following in itertools.pairwise(body):
            if (
                isinstance(node, ast.AnnAssign)
                and isinstance(node.target, ast.Name)
                and isinstance(following, ast.Expr)
                and isinstance(following.value, ast.Constant)
                and isinstance(following.value.value, str)
            ):
                docs[node.target.id] = " ".join(following.value.value.split())
    return docs


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def env_name(prefix: str, name: str) -> str:
    return f"{prefix}_{name.upper()}"


def _field_type(cls: type, field: dataclasses.Field) -> Any:
    return typing.get_type_hints(cls)[field.name]


def _is_tuple(kind: Any) -> bool:
    return typing.get_origin(kind) is tuple


def _scalar(kind: Any) -> type:
    """The concrete type behind ``int``, ``float | None``, ``tuple[int, ...]``, ..."""
    if _is_tuple(kind):
        return typing.get_args(kind)[0]
    args = [a for a in typing.get_args(kind) if a is not type(None)]
    return args[0] if args else kind


def add_options(
    parser: argparse.ArgumentParser,
    cls: type,
    env_prefix: str,
    title: str,
    *,
    skip: tuple[str, ...] = (),
    defaults: dict[str, Any] | None = None,
) -> None:
    """Add one flag per field of dataclass ``cls`` (except ``skip``) in an argument group.

    ``defaults`` overrides the dataclass defaults shown in --help and used when neither flag
    nor environment variable is given.
    """
    group = parser.add_argument_group(title, "each flag also reads the environment variable named in it")
    docs = field_docs(cls)
    defaults = defaults or {}
    for field in dataclasses.fields(cls):
        if field.name in skip:
            continue
        kind = _field_type(cls, field)
        default = defaults.get(field.name, _default(field))
        shown = " ".join(map(str, default)) if isinstance(default, tuple) else default
        help_text = (
            f"{docs.get(field.name, field.name)} [env {env_name(env_prefix, field.name)}; default {shown}]"
        )
        kwargs: dict[str, Any] = {"dest": f"opt_{field.name}", "default": None, "help": help_text}
        if kind is bool:
            group.add_argument(_flag(field.name), action=argparse.BooleanOptionalAction, **kwargs)
        elif _is_tuple(kind):
            metavar = "N" if _scalar(kind) in (int, float) else "NAME"
            group.add_argument(_flag(field.name), nargs="+", type=_scalar(kind), metavar=metavar, **kwargs)
        else:
            group.add_argument(_flag(field.name), type=_scalar(kind), metavar=field.name.upper(), **kwargs)
    parser.set_defaults(**{f"optdefaults_{cls.__name__}": defaults})


def _default(field: dataclasses.Field) -> Any:
    if field.default is not dataclasses.MISSING:
        return field.default
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    raise TypeError(f"config field {field.name} needs a default")


def _parse_env(raw: str, kind: Any, name: str) -> Any:
    scalar = _scalar(kind)
    try:
        if kind is bool:
            lowered = raw.strip().lower()
            if lowered not in ("1", "true", "yes", "on", "0", "false", "no", "off"):
                raise ValueError(raw)
            return lowered in ("1", "true", "yes", "on")
        if _is_tuple(kind):
            return tuple(scalar(p) for p in raw.replace(",", " ").split())
        return scalar(raw.strip())
    except ValueError:
        raise OptionError(f"{name}={raw!r} is not a valid {getattr(scalar, '__name__', scalar)}") from None


def options_from_args(cls: type[T], args: argparse.Namespace | None, env_prefix: str, **overrides: Any) -> T:
    """Build ``cls`` from parsed flags, then environment variables, then defaults; ``overrides`` win."""
    defaults = getattr(args, f"optdefaults_{cls.__name__}", {}) if args is not None else {}
    values: dict[str, Any] = {}
    for field in dataclasses.fields(cls):
        kind = _field_type(cls, field)
        value = getattr(args, f"opt_{field.name}", None) if args is not None else None
        env = env_name(env_prefix, field.name)
        if value is None and os.environ.get(env, "").strip():
            value = _parse_env(os.environ[env], kind, env)
        if value is None and field.name in defaults:
            value = defaults[field.name]
        if value is not None:
            values[field.name] = tuple(value) if _is_tuple(kind) else value
    values.update(overrides)
    try:
        return cls(**values)
    except (TypeError, ValueError) as exc:
        raise OptionError(str(exc)) from None

"""Flags and environment variables from one flat, documented config dataclass.

Every service keeps its settings in a dataclass whose fields carry a one-line
docstring (cleanrl style). :func:`add_options` turns the fields into ``--flags``
(the docstring is the help text) that also read ``<PREFIX>_<FIELD>`` environment
variables; :func:`options_from_args` resolves flag > environment > default.

A field's ``metadata`` may rename its flag (``flag``), its environment variable
(``env``) or its metavar (``metavar``) and restrict its values (``choices``); a
``list[str]`` field is a repeatable flag whose environment variable is
comma-separated. A field whose type is itself a dataclass (a Q-network variant's own config,
``NNQLConfig.local``) gives one option per field of it, named ``<field>_<subfield>``
(``--local-window``, ``NAVLEARN_NNQL_LOCAL_WINDOW``, a JSON object in a config file); see
:func:`option_fields`. This is the one option system: every command's config flags
(``up``, ``learner``, ``actor``, ``train``, ``nirl train``, ...) and the Zenoh flags
(services.common.transport.ZenohSettings) are built by it, so one field has one
spelling everywhere (tests/test_option_spelling.py lists them).

A field a command cannot honour is named in ``refuse`` with the reason: its flag, or its
environment variable, is refused while the arguments are parsed, in one sentence, before
anything starts (never silently ignored).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import functools
import inspect
import itertools
import json
import os
import pathlib
import textwrap
import typing
from typing import Any, TypeVar

T = TypeVar("T")


class OptionError(ValueError):
    """A flag or environment variable holds a value its field cannot take."""


class _Refused(argparse.Action):
    """A flag its command cannot honour: parsing it ends the parse with the reason."""

    def __init__(self, option_strings: list[str], dest: str, reason: str = "", **kwargs: Any) -> None:
        super().__init__(option_strings, dest, nargs="*", **kwargs)
        self.reason = reason

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        parser.error(f"{option_string}: {self.reason}")


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


@dataclasses.dataclass(frozen=True)
class Option:
    """One option of a config class: a field, or a field of a nested config field (``parent``)."""

    name: str
    """the option's name: the field's, or ``<parent>_<field>`` for a nested config's field"""
    owner: type
    """the dataclass declaring ``field``"""
    field: dataclasses.Field
    parent: str = ""
    """the nested config field of the top-level config holding ``field`` ("" for a top-level field)"""

    @property
    def flag(self) -> str:
        return (not self.parent and self.field.metadata.get("flag")) or "--" + self.name.replace("_", "-")

    @property
    def kind(self) -> Any:
        return _field_type(self.owner, self.field)


def _field_type(cls: type, field: dataclasses.Field) -> Any:
    return typing.get_type_hints(cls)[field.name]


def _nested(cls: type, field: dataclasses.Field) -> type | None:
    """The dataclass a field holds (a nested config), or None."""
    kind = _field_type(cls, field)
    return kind if dataclasses.is_dataclass(kind) else None


@functools.cache
def option_fields(cls: type) -> tuple[Option, ...]:
    """Every option of config class ``cls``: each field, and in place of a field holding a dataclass
    each of that dataclass' fields (one level: a variant's small config inside the learner's)."""
    options: list[Option] = []
    for field in dataclasses.fields(cls):
        inner = _nested(cls, field)
        if inner is None:
            options.append(Option(field.name, cls, field))
        else:
            options.extend(
                Option(f"{field.name}_{sub.name}", inner, sub, field.name)
                for sub in dataclasses.fields(inner)
            )
    return tuple(options)


def env_name(prefix: str, name: str, field: dataclasses.Field | None = None) -> str:
    if field is not None and field.metadata.get("env"):
        return field.metadata["env"]
    return f"{prefix}_{name.upper()}"


def _is_tuple(kind: Any) -> bool:
    return typing.get_origin(kind) is tuple


def _is_list(kind: Any) -> bool:
    """``list[str]`` or ``list[str] | None``: a repeatable flag."""
    args = [a for a in typing.get_args(kind) if a is not type(None)] if typing.get_origin(kind) else [kind]
    return any(typing.get_origin(a) is list for a in args)


def _scalar(kind: Any) -> type:
    """The concrete type behind ``int``, ``float | None``, ``tuple[int, ...]``, ..."""
    if _is_tuple(kind):
        return typing.get_args(kind)[0]
    if _is_list(kind):
        return str
    args = [a for a in typing.get_args(kind) if a is not type(None)]
    return args[0] if args else kind


def add_options(
    parser: argparse.ArgumentParser,
    cls: type,
    env_prefix: str,
    title: str,
    *,
    skip: tuple[str, ...] = (),
    refuse: dict[str, str] | None = None,
    defaults: dict[str, Any] | None = None,
    dest_prefix: str = "opt_",
    description: str = "each flag also reads the environment variable named in it",
) -> None:
    """Add one flag per field of dataclass ``cls`` (except ``skip``) in an argument group.

    ``skip`` leaves fields to the command (it sets them itself); ``refuse`` maps fields the command
    cannot honour to the reason, said when their flag or environment variable is given (the flag is
    hidden from --help); a nested config field named there refuses each of its options. ``defaults``
    overrides the dataclass defaults shown in --help and used when neither flag nor environment
    variable is given; ``dest_prefix`` names the parsed attributes (``<dest_prefix><option name>``),
    for :func:`options_from_args` with the same prefix. Each option is one of :func:`option_fields`.
    """
    group = parser.add_argument_group(title, description)
    defaults = defaults or {}
    refuse = refuse or {}
    for option in option_fields(cls):
        field, top = option.field, option.parent or option.name
        if top in skip:
            continue
        reason = refuse.get(top, refuse.get(option.name))
        if reason is not None:
            group.add_argument(
                option.flag,
                action=_Refused,
                reason=reason,
                dest=argparse.SUPPRESS,
                default=argparse.SUPPRESS,
                help=argparse.SUPPRESS,
            )
            continue
        kind = option.kind
        default = defaults.get(option.name, _default(field))
        shown = " ".join(map(str, default)) if isinstance(default, tuple | list) else default
        if field.metadata.get("shown"):
            shown = field.metadata["shown"]
        doc = field_docs(option.owner).get(field.name, option.name)
        help_text = (f"{doc} [env {env_name(env_prefix, option.name, field)}; default {shown}]").replace(
            "%", "%%"
        )
        kwargs: dict[str, Any] = {"dest": f"{dest_prefix}{option.name}", "default": None, "help": help_text}
        metavar = field.metadata.get("metavar")
        if kind is bool:
            group.add_argument(option.flag, action=argparse.BooleanOptionalAction, **kwargs)
        elif _is_list(kind):
            group.add_argument(option.flag, action="append", metavar=metavar or "VALUE", **kwargs)
        elif _is_tuple(kind):
            metavar = metavar or ("N" if _scalar(kind) in (int, float) else "NAME")
            group.add_argument(option.flag, nargs="+", type=_scalar(kind), metavar=metavar, **kwargs)
        elif "choices" in field.metadata:
            group.add_argument(option.flag, choices=field.metadata["choices"], **kwargs)
        else:
            metavar = metavar or option.name.upper()
            group.add_argument(option.flag, type=_scalar(kind), metavar=metavar, **kwargs)
    parser.set_defaults(**{f"optdefaults_{cls.__name__}": defaults, f"optrefused_{cls.__name__}": refuse})


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
        if _is_list(kind):
            return [p.strip() for p in raw.split(",") if p.strip()]
        return scalar(raw.strip())
    except ValueError:
        raise OptionError(f"{name}={raw!r} is not a valid {getattr(scalar, '__name__', scalar)}") from None


def options_from_args(
    cls: type[T],
    args: argparse.Namespace | None,
    env_prefix: str,
    *,
    dest_prefix: str = "opt_",
    base: dict[str, Any] | None = None,
    **overrides: Any,
) -> T:
    """Build ``cls`` from parsed flags, then ``base`` (a config file's fields; a nested config's as an
    object), then environment variables, then defaults; ``overrides`` win. An environment variable of
    a field the command refuses (``add_options(refuse=...)``) is an OptionError naming the reason."""
    defaults = getattr(args, f"optdefaults_{cls.__name__}", {}) if args is not None else {}
    refused = getattr(args, f"optrefused_{cls.__name__}", {}) if args is not None else {}
    base = base or {}
    values: dict[str, Any] = {}
    nested: dict[str, dict[str, Any]] = {}
    for option in option_fields(cls):
        field, kind, top = option.field, option.kind, option.parent or option.name
        reason = refused.get(top, refused.get(option.name))
        value = getattr(args, f"{dest_prefix}{option.name}", None) if args is not None else None
        env = env_name(env_prefix, option.name, field)
        if reason is not None and os.environ.get(env, "").strip():
            raise OptionError(f"{env}: {reason}")
        from_file = (base.get(option.parent) or {}).get(field.name) if option.parent else base.get(field.name)
        if from_file is not None and _is_tuple(kind):
            from_file = tuple(from_file)  # JSON has lists
        if reason is not None and from_file is not None and from_file != _default(field):
            raise OptionError(f"{option.name} {from_file!r} (config file): {reason}")
        if value is None:
            value = from_file
        if value is None and os.environ.get(env, "").strip():
            value = _parse_env(os.environ[env], kind, env)
        if value is None and option.name in defaults:
            value = defaults[option.name]
        if value is not None:
            value = tuple(value) if _is_tuple(kind) else value
            if option.parent:
                nested.setdefault(option.parent, {})[field.name] = value
            else:
                values[field.name] = value
    try:
        for name, given in nested.items():
            if name not in overrides:
                values[name] = _nested(cls, next(f for f in dataclasses.fields(cls) if f.name == name))(
                    **given
                )
        values.update(overrides)
        return cls(**values)
    except (TypeError, ValueError) as exc:
        raise OptionError(str(exc)) from None


def config_file(path: str | None, cls: type) -> dict:
    """The fields of ``cls`` a JSON config file holds ({} without one); unknown fields are an error."""
    if not path:
        return {}
    loaded = json.loads(pathlib.Path(path).read_text())
    if not isinstance(loaded, dict):
        raise ValueError(f"{path}: expected a JSON object of {cls.__name__} fields")
    unknown = sorted(set(loaded) - {f.name for f in dataclasses.fields(cls)})
    if unknown:
        raise ValueError(f"{path}: unknown {cls.__name__} field(s) {unknown}")
    return loaded

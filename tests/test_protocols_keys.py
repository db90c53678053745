"""The navlearn key space: builders, parser, and names that would break it."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols import keys
from protocols.errors import ProtocolError

good_names = st.from_regex(r"[A-Za-z0-9_][A-Za-z0-9_.:@+=-]{0,63}", fullmatch=True)


def test_builders() -> None:
    assert keys.transitions("run1", "actor-0") == "navlearn/run1/transitions/actor-0"
    assert keys.demos("run1", "astar") == "navlearn/run1/demos/astar"
    assert keys.weights("run1", "nnql") == "navlearn/run1/weights/nnql"
    assert keys.evaluation("run1", "eval@host") == "navlearn/run1/eval/eval@host"
    assert keys.status("run1") == "navlearn/run1/status/learner"
    assert keys.acks("run1", "a1") == "navlearn/run1/acks/a1"
    assert keys.actor_status("run1", "a1") == "navlearn/run1/status/actor:a1"
    assert keys.parse(keys.actor_status("run1", "a1")).name == keys.ACTOR_STATUS_PREFIX + "a1"
    assert keys.alive("run1", "actor", "a1") == "navlearn/run1/alive/actor/a1"
    assert keys.everything("run1", "transitions") == "navlearn/run1/transitions/*"
    assert keys.everything("run1", "alive") == "navlearn/run1/alive/*/*"
    assert keys.alive_role("run1", "actor") == "navlearn/run1/alive/actor/*"


@settings(max_examples=50)
@given(run=good_names, name=good_names, role=good_names)
def test_parse_inverts_every_builder(run: str, name: str, role: str) -> None:
    for channel, key in (
        ("transitions", keys.transitions(run, name)),
        ("demos", keys.demos(run, name)),
        ("weights", keys.weights(run, name)),
        ("eval", keys.evaluation(run, name)),
        ("acks", keys.acks(run, name)),
    ):
        assert keys.parse(key) == keys.ParsedKey(run, channel, (name,))
    parsed = keys.parse(keys.alive(run, role, name))
    assert (parsed.run, parsed.channel, parsed.names, parsed.name) == (run, "alive", (role, name), name)
    assert keys.parse(keys.status(run)).name == "learner"


@pytest.mark.parametrize(
    "bad",
    [
        "",
        "a/b",
        "*",
        "**",
        "a*",
        "$x",
        "a$",
        "q?",
        "x#y",
        "a b",
        " a",
        "tab\t",
        "é",
        "-lead",
        ".",
        "x" * 65,
        5,
    ],
)
def test_names_that_would_break_the_key_space_are_rejected(bad) -> None:
    with pytest.raises(ProtocolError) as err:
        keys.transitions("run", bad)
    assert err.value.reason == "key"
    with pytest.raises(ProtocolError):
        keys.prefix(bad)


@pytest.mark.parametrize(
    "key",
    [
        "navlearn/run",
        "other/run/transitions/a",
        "navlearn/run/teleport/a",
        "navlearn/run/transitions/a/b",
        "navlearn/run/alive/actor",
        "navlearn/r*n/transitions/a",
        "navlearn/run/transitions/**",
    ],
)
def test_parse_rejects_keys_outside_the_space(key: str) -> None:
    with pytest.raises(ProtocolError) as err:
        keys.parse(key)
    assert err.value.reason == "key"


def test_zenoh_accepts_every_key_we_build() -> None:
    zenoh = pytest.importorskip("zenoh")
    key = keys.alive("r-1.x", "actor", "a:b@c+d=e-f.g_h")
    assert str(zenoh.KeyExpr(key)) == key
    assert zenoh.KeyExpr(keys.everything("r-1.x", "alive")).intersects(key)

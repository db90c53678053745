"""Unit tests of the services' pure parts: rate limiter, checkpoint rotation, outbox, options."""

from __future__ import annotations

import argparse
import json
import os
import threading
from dataclasses import dataclass
from pathlib import Path

import pytest

from agents.nnql.config import NNQLConfig
from agents.nnql.ratelimit import RateLimiter
from services.cli import build_parser, main
from services.commands.learner import config_file
from services.common.options import OptionError, add_options, field_docs, options_from_args
from services.common.outbox import Outbox
from services.learner.checkpoint import CheckpointDir

# ---------------------------------------------------------------- rate limiter


def test_no_update_before_min_size():
    limiter = RateLimiter(updates_per_insert=0.5, min_size=100, tolerance=4)
    limiter.inserted(99)
    assert not limiter.can_update(99)
    assert limiter.updates_allowed(99) == 0
    limiter.inserted(1)
    assert limiter.can_update(100)


def test_updates_track_the_ratio_within_the_tolerance():
    """Whatever the insert pattern, updates stay within tolerance of ratio * (inserts - min_size)."""
    ratio, min_size, tolerance = 0.125, 64, 8.0
    limiter = RateLimiter(ratio, min_size, tolerance)
    for batch in [64, 1, 7, 128, 3, 300, 2, 2, 2, 50]:
        if limiter.can_insert():
            limiter.inserted(batch)
        while limiter.can_update(limiter.inserts):
            limiter.updated()
        target = ratio * (limiter.inserts - min_size)
        assert target - tolerance - 1 <= limiter.updates <= target + tolerance


def test_trickle_does_not_buy_extra_updates():
    """After the learner has caught up, one transition buys ratio updates, not more."""
    limiter = RateLimiter(updates_per_insert=0.25, min_size=10, tolerance=2)
    limiter.inserted(10)
    ran = 0
    while limiter.can_update(10):
        limiter.updated()
        ran += 1
    assert ran == 2  # the tolerance lets it run 2 updates ahead, then it waits for data
    limiter.inserted(4)
    assert limiter.updates_allowed(14) == 1


def test_inserts_block_when_the_learner_falls_behind_and_reopen_after_updates():
    limiter = RateLimiter(updates_per_insert=0.5, min_size=10, tolerance=4)
    limiter.inserted(10)
    assert limiter.can_insert()
    limiter.inserted(20)  # 10 updates owed: more than the tolerance
    assert not limiter.can_insert()
    while not limiter.can_insert():
        assert limiter.can_update(30)  # never both closed: no deadlock
        limiter.updated()
    assert limiter.updates == 6


def test_limiter_validates_and_round_trips_state():
    with pytest.raises(ValueError):
        RateLimiter(0.0, 10, 4)
    with pytest.raises(ValueError):
        RateLimiter(0.5, 10, 0.5)
    a = RateLimiter(0.5, 10, 4)
    a.inserted(40)
    a.updated(7)
    b = RateLimiter(0.5, 10, 4)
    b.load_state(a.state())
    assert (b.inserts, b.updates, b.diff) == (40, 7, a.diff)


# ---------------------------------------------------------------- checkpoints


def _write(payload: str):
    def write(tmp: Path) -> None:
        (tmp / "data.txt").write_text(payload)
        (tmp / "sub").mkdir()
        (tmp / "sub" / "more.txt").write_text(payload * 2)

    return write


def test_checkpoints_rotate_and_latest_is_newest(tmp_path):
    ckpts = CheckpointDir(tmp_path, keep=2)
    assert ckpts.latest() is None
    paths = [ckpts.save(_write(str(i))) for i in range(4)]
    assert [p.name for p in ckpts.all()] == ["ckpt-00000003", "ckpt-00000004"]
    assert ckpts.latest() == paths[-1]
    assert (ckpts.latest() / "data.txt").read_text() == "3"
    assert not paths[0].exists()


def test_failed_write_leaves_no_checkpoint_and_keeps_the_previous(tmp_path):
    ckpts = CheckpointDir(tmp_path, keep=3)
    good = ckpts.save(_write("good"))

    def broken(tmp: Path) -> None:
        (tmp / "data.txt").write_text("half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        ckpts.save(broken)
    assert ckpts.all() == [good]
    assert (ckpts.latest() / "data.txt").read_text() == "good"
    assert [p.name for p in tmp_path.iterdir()] == [good.name]


def test_leftover_temporary_directory_is_ignored_then_removed(tmp_path):
    ckpts = CheckpointDir(tmp_path)
    good = ckpts.save(_write("good"))
    crashed = tmp_path / ".tmp-ckpt-00000002-999"  # a writer killed mid-checkpoint
    crashed.mkdir()
    (crashed / "data.txt").write_text("partial")
    reader = CheckpointDir(tmp_path)
    assert reader.latest() == good
    assert crashed.exists()  # a reader leaves it: the writer may still be filling it
    reader.remove_unfinished()  # the writer, on its next start
    assert not crashed.exists()
    assert ckpts.save(_write("next")).name == "ckpt-00000002"


# ---------------------------------------------------------------- outbox


class Wire:
    def __init__(self) -> None:
        self.sent: list[bytes] = []
        self.reachable = True


def test_outbox_keeps_at_most_window_unacknowledged():
    wire = Wire()
    outbox = Outbox(wire.sent.append, lambda: wire.reachable, capacity=8, window=2, ack_timeout=60)
    stop = threading.Event()
    for seq in (1, 2):
        outbox.put(seq, b"%d" % seq)
        outbox.flush(stop)
    assert wire.sent == [b"1", b"2"] and outbox.in_flight == 2
    outbox.put(3, b"3")
    acker = threading.Timer(0.3, outbox.on_ack, args=(1,))
    acker.start()
    outbox.flush(stop)  # waits for the acknowledgement of batch 1
    acker.join()
    assert wire.sent == [b"1", b"2", b"3"] and outbox.acked_seq == 1


def test_outbox_holds_batches_while_unreachable_and_sends_them_in_order():
    wire = Wire()
    wire.reachable = False
    outbox = Outbox(wire.sent.append, lambda: wire.reachable, capacity=3, window=10)
    stop = threading.Event()
    for seq in (1, 2):
        outbox.put(seq, b"%d" % seq)
        outbox.flush(stop)  # returns at once: room left
    assert wire.sent == [] and len(outbox) == 2
    outbox.put(3, b"3")
    threading.Timer(0.3, lambda: setattr(wire, "reachable", True)).start()
    threading.Timer(0.6, lambda: [outbox.on_ack(s) for s in (1, 2, 3)]).start()
    outbox.flush(stop)  # full: waits for the learner, sends everything, waits for room (the acks)
    assert wire.sent == [b"1", b"2", b"3"] and len(outbox) == 0 and outbox.acked == 3


def test_outbox_resends_unacknowledged_batches_after_the_timeout():
    wire = Wire()
    outbox = Outbox(wire.sent.append, lambda: True, capacity=4, window=1, ack_timeout=0.2)
    stop = threading.Event()
    outbox.put(1, b"1")
    outbox.flush(stop)
    outbox.put(2, b"2")
    threading.Timer(0.5, outbox.on_ack, args=(1,)).start()
    outbox.flush(stop)  # no ack for 1 within 0.2 s: sent again until it is acknowledged, then 2
    assert wire.sent[:2] == [b"1", b"1"] and wire.sent[-1] == b"2" and set(wire.sent) == {b"1", b"2"}
    assert outbox.resent >= 1 and outbox.acked == 1 and outbox.in_flight == 1


def test_outbox_resends_unacknowledged_batches_when_the_learner_is_back():
    wire = Wire()
    outbox = Outbox(wire.sent.append, lambda: wire.reachable, capacity=8, window=4, ack_timeout=60)
    stop = threading.Event()
    for seq in (1, 2):
        outbox.put(seq, b"%d" % seq)
        outbox.flush(stop)
    outbox.on_ack(1)
    wire.reachable = False  # the learner dies before acknowledging 2
    outbox.put(3, b"3")
    outbox.flush(stop)
    assert wire.sent == [b"1", b"2"] and len(outbox) == 2
    wire.reachable = True
    outbox.flush(stop)
    assert wire.sent == [b"1", b"2", b"2", b"3"] and outbox.resent == 1


# ---------------------------------------------------------------- options


@dataclass
class DemoConfig:
    """For the options tests."""

    envs: int = 8
    """robots per actor"""
    maps: str = "mixed:16"
    """map spec"""
    sizes: tuple[int, ...] = (32, 32)
    """layer sizes"""
    fast: bool = False
    """go fast"""
    rate: float | None = None
    """optional rate"""


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_options(parser, DemoConfig, "T_DEMO", "demo")
    return parser.parse_args(argv)


def test_field_docs_become_help():
    assert field_docs(DemoConfig)["envs"] == "robots per actor"
    parser = argparse.ArgumentParser()
    add_options(parser, DemoConfig, "T_DEMO", "demo")
    text = parser.format_help()
    assert "robots per actor [env T_DEMO_ENVS; default 8]" in " ".join(text.split())


def test_flag_beats_environment_beats_default(monkeypatch):
    monkeypatch.setenv("T_DEMO_ENVS", "3")
    monkeypatch.setenv("T_DEMO_SIZES", "16, 8")
    monkeypatch.setenv("T_DEMO_FAST", "yes")
    config = options_from_args(DemoConfig, _parse(["--maps", "rooms:20", "--rate", "0.5"]), "T_DEMO")
    assert config == DemoConfig(envs=3, maps="rooms:20", sizes=(16, 8), fast=True, rate=0.5)
    config = options_from_args(DemoConfig, _parse(["--envs", "5", "--no-fast"]), "T_DEMO")
    assert (config.envs, config.fast) == (5, False)
    assert "T_DEMO_MAPS" not in os.environ and config.maps == "mixed:16"


def test_bad_environment_value_is_one_clear_error(monkeypatch):
    monkeypatch.setenv("T_DEMO_ENVS", "many")
    with pytest.raises(OptionError, match="T_DEMO_ENVS='many' is not a valid int"):
        options_from_args(DemoConfig, _parse([]), "T_DEMO")


@pytest.mark.parametrize("command", ["learner", "up"])
def test_distributed_commands_refuse_sarsa(command, monkeypatch, capsys):
    monkeypatch.setenv("NAVLEARN_NNQL_SARSA", "1")
    monkeypatch.setenv("NAVLEARN_NNQL_DOUBLE_Q", "0")
    assert main([command]) == 2
    assert "navlearn train --local --sarsa" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["learner", "up"])
@pytest.mark.parametrize(
    ("flags", "reason"),
    [
        (["--sarsa"], "navlearn train --local --sarsa"),
        (["--patch-goal"], "own-map patch"),
        (["--patch-embed", "64"], "own-map patch"),
        (["--patch-channels", "8", "16"], "own-map patch"),
        (["--patch-strides", "1", "1"], "own-map patch"),
        (["--patch-window", "3"], "own-map patch"),
    ],
)
def test_distributed_commands_refuse_what_they_cannot_honour_while_parsing(command, flags, reason, capsys):
    """Flags the learner service cannot honour end the parse in one sentence, before anything starts."""
    with pytest.raises(SystemExit) as exit_:
        main([command, *flags])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert f"{flags[0]}: " in err and reason in err


def test_learner_reads_its_nnql_config_from_a_file_and_flags_win(tmp_path, monkeypatch):
    """`up` hands the learner its NNQLConfig as a file (not re-parsed environment variables)."""
    path = tmp_path / "nnql.json"
    path.write_text(json.dumps(NNQLConfig(gamma=0.9, hidden_sizes=(32, 16), seed=4).to_dict()))
    monkeypatch.setenv("NAVLEARN_NNQL_GAMMA", "0.5")  # the file wins over the environment
    args = build_parser().parse_args(["learner", "--nnql-config", str(path), "--lr", "0.01"])
    nnql = options_from_args(
        NNQLConfig, args, "NAVLEARN_NNQL", base=config_file(args.nnql_config, NNQLConfig)
    )
    assert (nnql.gamma, nnql.hidden_sizes, nnql.seed, nnql.lr) == (0.9, (32, 16), 4, 0.01)
    path.write_text(json.dumps({"patch": {"goal": True}}))
    with pytest.raises(OptionError, match="own-map patch"):
        options_from_args(NNQLConfig, args, "NAVLEARN_NNQL", base=config_file(args.nnql_config, NNQLConfig))
    path.write_text(json.dumps({"gama": 0.9}))
    with pytest.raises(ValueError, match=r"unknown NNQLConfig field\(s\) \['gama'\]"):
        config_file(str(path), NNQLConfig)

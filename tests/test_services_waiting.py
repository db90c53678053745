"""Waiting is never silent and bad arguments are one plain sentence: the CLI's own messages.

No learner, a wrong --run, no router, malformed or unresolvable endpoints, a bad map for
`navlearn up`: each test runs the real command and checks its exit code and its words.
"""

from __future__ import annotations

import argparse
import os
import re
import socket
import time

import pytest
from conftest import free_port
from wire_helpers import small_learner, start, stop, wait_for_line

from protocols import keys
from services.cli import HelpFormatter, build_parser, main
from services.common.transport import ZenohSettings, open_session
from services.ops.status import progress_line

BAD_ENDPOINTS = [
    ("127.0.0.1:7447", "has no protocol: write it as tcp/127.0.0.1:7447"),
    ("tcp/127.0.0.1", "has no port: write it as tcp/127.0.0.1:7447"),
    ("tcp/127.0.0.1:http", "port 'http' is not a number"),
    ("tcp/nohost.invalid:7447", "host name 'nohost.invalid' "),  # does not resolve (or no DNS answer)
    ("carrier/127.0.0.1:7447", "names protocol 'carrier', which Zenoh does not know"),
]
RUST = re.compile(r"Json5Err|\.rs:\d|cargo|Location \{")


@pytest.fixture(autouse=True)
def clean_env(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in list(os.environ):
        if name.startswith("NAVLEARN_"):
            monkeypatch.delenv(name)


@pytest.mark.parametrize("command", ["status", "actor", "evaluator", "learner"])
@pytest.mark.parametrize(("endpoint", "words"), BAD_ENDPOINTS)
def test_a_bad_endpoint_is_one_plain_sentence_before_zenoh_sees_it(command, endpoint, words, capsys):
    start_time = time.monotonic()
    assert main([command, "--connect", endpoint]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and f"navlearn {command}: --connect {endpoint!r}" in err
    assert len(err.splitlines()) == 1 and not RUST.search(err)
    assert time.monotonic() - start_time < 10


def test_a_bad_listen_endpoint_is_refused_too(capsys):
    assert main(["router", "--listen", "0.0.0.0:7447"]) == 2
    assert "--listen '0.0.0.0:7447' has no protocol: write it as tcp/0.0.0.0:7447" in capsys.readouterr().err


def test_status_without_a_router_fails_fast_naming_endpoint_and_run(capsys):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    start_time = time.monotonic()
    assert main(["status", "--connect", endpoint, "--run", "nobody", "--connect-timeout", "1"]) == 2
    err = capsys.readouterr().err
    assert f"no Zenoh router answered at {endpoint} within 1 s (run 'nobody')" in err
    assert not RUST.search(err) and time.monotonic() - start_time < 10


@pytest.fixture
def router_with_a_learner_token_on_run_b():
    """A router (this process) and a liveliness token as a learner of run 'b' would hold it."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = open_session(ZenohSettings(mode="router", listen=[endpoint]))
    with router, router.liveliness().declare_token(keys.alive("b", "learner", "learner")):
        yield endpoint


def test_status_on_a_run_without_learner_names_the_run_and_the_one_that_has_it(
    router_with_a_learner_token_on_run_b, capsys
):
    endpoint = router_with_a_learner_token_on_run_b
    assert main(["status", "--connect", endpoint, "--run", "a", "--timeout", "1"]) == 1
    err = capsys.readouterr().err
    assert f"no answer on navlearn/a/status/learner via {endpoint} within 1 s" in err
    assert "no learner on run 'a', but on 'b': give --run b" in err


def test_an_actor_without_router_says_where_and_for_which_run_at_once_then_gives_up():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    argv = ["-m", "services.cli", "actor", "--connect", endpoint, "--run", "r7", "--envs", "1",
            "--connect-timeout", "5"]  # fmt: skip
    proc, lines = start(argv)
    try:
        assert proc.wait(timeout=240) == 2, "\n".join(lines)
    finally:
        stop(proc)
    waiting = [line for line in lines if f"waiting for a Zenoh router at {endpoint} for run 'r7'" in line]
    assert len(waiting) >= 2, "\n".join(lines)  # at once, then again after 2 s (back-off)
    assert "(0 s so far" in waiting[0]
    assert f"no Zenoh router answered at {endpoint} within 5 s (run 'r7')" in lines[-1]
    assert "None" not in "\n".join(lines)


def _actor(endpoint: str, run: str):
    argv = ["-m", "services.cli", "actor", "--connect", endpoint, "--run", run, "--id", "a1",
            "--envs", "1", "--batch-steps", "1", "--silence-warning", "2"]  # fmt: skip
    return start(argv)


def test_an_actor_on_a_wrong_run_says_so_and_names_the_run_the_learner_is_on(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with small_learner(endpoint, "b", tmp_path / "ckpt"):
        proc, lines = _actor(endpoint, "a")
        try:
            line = wait_for_line(lines, "no acknowledgement from the learner on run 'a'", timeout=240)
            assert f"via {endpoint}" in line and "no learner on run 'a', but on 'b': give --run b" in line
        finally:
            assert stop(proc) == 0


def test_an_actor_with_no_learner_anywhere_says_so():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with open_session(ZenohSettings(mode="router", listen=[endpoint])):
        proc, lines = _actor(endpoint, "lonely")
        try:
            line = wait_for_line(lines, "no acknowledgement from the learner on run 'lonely'", timeout=240)
            assert "no learner on run 'lonely' holds a liveliness token here" in line
        finally:
            assert stop(proc) == 0


def test_up_checks_its_map_before_starting_anything(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["up", "--maps", str(tmp_path / "BADFILE"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "navlearn up: --maps: map spec" in err and "BADFILE" in err and "nor an existing map file" in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("flags", "words"),
    [
        (["--actors", "0"], "--actors 0: needs at least 1"),
        (["--duration", "-5"], "--duration -5.0: must be 0 or more"),
        (["--run", "a/b"], "run 'a/b' may only use"),
        (["--port", "99999"], "--port 99999: must be 0 (a free port) or 1 to 65535"),
    ],
)
def test_up_checks_cheap_arguments_before_starting_anything(tmp_path, capsys, flags, words):
    out = tmp_path / "run"
    assert main(["up", "--out", str(out), *flags]) == 2
    assert words in capsys.readouterr().err and not out.exists()


def test_up_refuses_a_port_in_use_before_starting_anything(tmp_path, capsys):
    out = tmp_path / "run"
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        assert main(["up", "--out", str(out), "--port", str(port)]) == 2
    assert f"--port {port}: already in use" in capsys.readouterr().err and not out.exists()


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


@pytest.mark.parametrize("command", sorted(_subparsers()))
def test_every_help_page_shows_the_defaults(command):
    parser = _subparsers()[command]
    formatter = parser._get_formatter()
    assert isinstance(formatter, HelpFormatter)
    for action in parser._actions:
        if not action.option_strings or action.default is None or action.default is False:
            continue
        if action.default == argparse.SUPPRESS:
            continue
        shown = formatter._get_help_string(action) % {"default": action.default}
        assert "default" in shown.lower(), f"{command} {action.option_strings[0]}: {shown}"
    assert "show this help message" in parser.format_help()


def test_the_progress_line_fits_an_80_column_terminal():
    learner = {
        "versions": {"nnql": 12345},
        "replay_sizes": {"transitions": 100_000},
        "rates": {"updates_per_s": 160.0, "transitions_per_s": 12345.0, "policy_lag": 2.5},
        "counters": {"transitions_rejected": 0},
        "last_eval": {
            "policy_version": 12300,
            "families": {"unseen": {"success": 0.75}, "dynamic": {"success": 0.5}},
        },
    }
    view = {"alive": {"actor": ["a1", "a2"]}, "learner": learner}
    line = progress_line(view, actors_expected=2)
    assert line == "v12345  160 upd/s  12k tr/s  replay 100k  lag 2.5  eval u75% d50%"
    assert len("[100/900 s] " + line) <= 80
    learner["counters"]["transitions_rejected"] = 123456
    view["alive"]["actor"] = ["a1"]
    line = progress_line(view, actors_expected=2)
    assert len("[100/900 s] " + line) <= 80 and line.endswith("...")
    assert "actors 1/2" in line


def test_the_learning_curve_lays_launches_end_to_end_and_does_not_join_a_resumed_run(tmp_path):
    """Issue 43: on wall time since the first launch, a few resumes left clumps in empty space; the
    time panel now counts training time, each launch starting where the one before ended."""
    import matplotlib.pyplot as plt

    from agents.evaluation.plots import evaluations_figure, plot_evaluations

    def point(version: int, time_s: float, launch: float) -> dict:
        success = {"value": 0.5, "low": 0.3, "high": 0.7}
        metrics = {"unseen": {"success": success, "path_ratio": 1.2}}
        return {"policy_version": version, "time": time_s, "launch": launch, "model": "nnql",
                "metrics": metrics}  # fmt: skip

    t0 = 1_000_000.0
    points = [point(10, t0 + 60, t0), point(20, t0 + 120, t0), point(30, t0 + 900, t0 + 600),
              point(40, t0 + 960, t0 + 600)]  # fmt: skip
    fig = evaluations_figure(points)
    wall = fig.axes[1]  # success against wall time
    segments = [line.get_xdata() for line in wall.get_lines() if line.get_marker() == "o"]
    # minutes of training: the second launch (10 min after the first) continues at 2 min, 5 min in
    assert [list(x) for x in segments] == [[1.0, 2.0], [7.0, 8.0]]
    marks = [line.get_xdata()[0] for line in wall.get_lines() if line.get_linestyle() == ":"]
    assert marks == [2.0]  # the resume, where the first launch's training ended
    assert "launches end to end" in fig.axes[3].get_xlabel()
    legend = fig.axes[1].get_legend()  # beside the panels, not over the curves
    fig.canvas.draw()
    box, panel = legend.get_window_extent(), fig.axes[1].get_window_extent()
    assert box.x0 >= panel.x1
    plt.close(fig)
    assert plot_evaluations(points, tmp_path / "curve.png").stat().st_size > 10_000


def test_status_shows_nirl_version_and_demonstrations_per_source():
    from protocols.messages import StatusReport
    from services.ops.status import render, status_dict

    status = StatusReport(
        sender="learner",
        counters={"demo_episodes/astar": 20, "demo_steps/astar": 487, "demo_episodes/human": 2,
                  "demo_steps/human": 61, "demo_steps": 548, "updates": 900},
        versions={"nnql": 900, "nirl": 640},
        replay_sizes={"transitions": 5000, "demos": 548},
        losses={"nirl/iq_loss": -0.5, "nirl/learned_reward": 0.03},
    )  # fmt: skip
    view = status_dict(status, [("demonstrator", "astar-1"), ("learner", "learner")])
    assert view["learner"]["demos"] == {
        "astar": {"episodes": 20, "steps": 487}, "human": {"episodes": 2, "steps": 61},
    }  # fmt: skip
    line = progress_line(view, actors_expected=1)
    assert line.startswith("v900  nirl v640 demos 548  ") and len("[100/900 s] " + line) <= 80
    from rich.console import Console

    console = Console(width=120, record=True)
    console.print(render(view))
    text = console.export_text()
    assert "demos per source" in text and "policy version (nirl)" in text
    assert "loss: nirl/iq_loss" in text and "human" in text


@pytest.fixture
def router_with_passwords(tmp_path):
    """A router (this process) that takes only alice:secret (usrpwd authentication)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    (tmp_path / "users").write_text("alice:secret\n")
    settings = ZenohSettings(mode="router", listen=[endpoint], auth_dictionary=str(tmp_path / "users"))
    with open_session(settings):
        yield endpoint, tmp_path


@pytest.mark.parametrize(
    ("line", "sent"), [("alice:wrong", "as user 'alice'"), ("bob:secret", "as user 'bob'")]
)
def test_wrong_credentials_are_told_apart_from_a_missing_router(router_with_passwords, line, sent, capsys):
    """Issue 43: a wrong password or unknown user was told "no Zenoh router answered ... start the
    learner"; Zenoh says "Unable to connect" either way, but the router's port does answer."""
    endpoint, tmp_path = router_with_passwords
    (tmp_path / "mine").write_text(line + "\n")
    argv = ["status", "--connect", endpoint, "--run", "r", "--connect-timeout", "1"]
    assert main([*argv, "--credentials", str(tmp_path / "mine")]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert f"no Zenoh session at {endpoint} within 1 s (run 'r'): a router listens at {endpoint}" in err
    assert f"refused this session {sent}: the user or password is wrong;" in err
    assert "--auth-dictionary" in err and "start the learner" not in err and not RUST.search(err)
    assert main(argv) == 2  # no credentials at all
    assert "refused this session without a user and password" in capsys.readouterr().err
    (tmp_path / "mine").write_text("alice:secret\n")  # the right ones: the session opens
    assert main([*argv, "--credentials", str(tmp_path / "mine"), "--timeout", "0.5"]) == 1


def test_a_missing_router_is_not_blamed_on_credentials(tmp_path, capsys):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    (tmp_path / "mine").write_text("alice:secret\n")
    argv = ["status", "--connect", endpoint, "--connect-timeout", "1"]
    assert main([*argv, "--credentials", str(tmp_path / "mine")]) == 2
    err = capsys.readouterr().err
    assert f"no Zenoh router answered at {endpoint} within 1 s (run 'default'): nothing listens there;" in err
    assert "refused" not in err and "credentials" not in err

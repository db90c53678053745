"""One run, one observation: `--observation` of `up` reaches every process it starts; weights say
what their network observes (``WeightsUpdate.observation``) and an actor or evaluator of another
observation refuses them naming the setting and the flag to give; a learner does not resume a
checkpoint of another observation. The whole `up --nirl` path in ``learning_plan`` runs end to end
in tests/test_nirl_up.py."""

from __future__ import annotations

import json
import logging
import re
import subprocess
import sys
import time

import msgpack
import numpy as np
import pytest
from conftest import free_port
from test_wire_zenoh import client, router, wait_until  # noqa: F401 (router: the fixture)
from wire_helpers import small_learner, start, stop, wait_for_line

from agents.nnql.config import NNQLConfig
from agents.nnql.learner import NNQLLearner
from protocols.codec import decode, encode, ext_hook
from protocols.errors import ProtocolError
from protocols.messages import WeightsUpdate
from services.actor.config import ActorConfig
from services.cli import build_parser, main
from services.common.options import options_from_args
from services.common.weights import WeightsBroadcaster, WeightsReceiver
from services.demonstrator.config import DemonstratorConfig
from services.evaluator.config import EvaluatorConfig
from services.learner.config import LearnerConfig
from services.ops.up import Up
from services.ops.up_config import UpConfig
from worlds.config import LEARNING_NAV, LEARNING_PLAN_NAV, OBSERVATION_ENV, observation_settings
from worlds.perception import observation_dim

TENSORS = {"0.weight": np.ones((4, 3), np.float32)}


def navlearn(*argv: str) -> subprocess.CompletedProcess:
    """The real command line, as a user runs it; must exit 0."""
    done = subprocess.run(
        [sys.executable, "-m", "services.cli", *argv], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, (argv, done.stdout, done.stderr)
    return done


def test_weights_carry_what_their_network_observes_inside_the_architecture() -> None:
    settings = observation_settings(LEARNING_PLAN_NAV)
    wire = encode(WeightsUpdate(model="nirl", version=3, tensors=TENSORS, observation=settings))
    assert msgpack.unpackb(wire, ext_hook=ext_hook, raw=False)["b"]["architecture"]["observation"] == settings
    decoded = decode(wire)
    assert decoded.observation == settings and "observation" not in decoded.architecture
    assert decode(encode(WeightsUpdate(model="m", version=1, tensors={}))).observation is None


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (["sensors.n_beams", 24], "must be a map"),
        ({"sensors.n_beams": [24]}, "must be a number, bool or string"),
    ],
)
def test_a_malformed_observation_record_is_rejected(value: object, text: str) -> None:
    wire = encode(WeightsUpdate(model="m", version=1, tensors={}, architecture={"observation": value}))
    with pytest.raises(ProtocolError, match=text):
        decode(wire)


@pytest.mark.integration
def test_a_process_of_another_observation_refuses_the_weights_naming_the_setting(router, caplog) -> None:  # noqa: F811
    run = "obsrun"
    with client(router) as learner_side, client(router) as other_side:
        plan = WeightsReceiver(other_side, run, "nnql", observation="learning_plan")
        same = WeightsReceiver(other_side, run, "nnql", observation="learning")
        broadcaster = WeightsBroadcaster(learner_side, run, "nnql", sender="learner")
        try:
            time.sleep(0.5)  # the subscriptions reach the router
            with caplog.at_level(logging.WARNING, logger="navlearn.weights"):
                for version in (1, 2):
                    broadcaster.publish(TENSORS, version, {}, observation=observation_settings(LEARNING_NAV))
                wait_until(lambda: plan.rejected["observation"] == 2, 10, "both updates refused")
                wait_until(lambda: same.received == 2, 10, "both updates taken")
            assert plan.take() is None and plan.received == 0
            assert same.take().message.version == 2
            refusals = [r.getMessage() for r in caplog.records if "ignoring weights" in r.getMessage()]
            assert len(refusals) == 1, refusals  # said once per sender, counted every time
            assert "observation.plan_length=False (this process has True)" in refusals[0]
            assert "--observation learning_plan: start it with --observation learning" in refusals[0]
        finally:
            for closing in (broadcaster, plan, same):
                closing.close()


def _learner(nav) -> NNQLLearner:
    config = NNQLConfig(hidden_sizes=(8,), batch_size=4, learning_starts=4)
    return NNQLLearner(config, observation_dim(nav), 5, observation=observation_settings(nav))


def test_a_learner_does_not_resume_a_checkpoint_of_another_observation() -> None:
    state = _learner(LEARNING_NAV).state_dict()
    wrong = r"observation.plan_length=False \(this learner has True\): resume it with the --observation"
    with pytest.raises(ValueError, match=wrong):
        _learner(LEARNING_PLAN_NAV).load_state_dict(state)
    # a record written before plan_length existed lacks it: off, so it resumes in LEARNING_NAV
    state["observation"] = {k: v for k, v in state["observation"].items() if k != "observation.plan_length"}
    _learner(LEARNING_NAV).load_state_dict(state)


def test_up_gives_every_process_its_observation(tmp_path) -> None:
    config = UpConfig(out=str(tmp_path / "run"), actors=2, nirl=True, observation="learning_plan")
    up = Up(config, NNQLConfig())
    started: dict[str, list[str]] = {}
    up._spawn = lambda name, argv, env: started.__setitem__(name, argv)
    up.start()
    assert set(started) == {"learner", "demonstrator", "actor-1", "actor-2", "evaluator"}
    for name, argv in started.items():
        at = argv.index("--observation")
        assert argv[at + 1] == "learning_plan" and argv.count("--observation") == 1, (name, argv)


SERVICES = {"actor": ActorConfig, "learner": LearnerConfig, "evaluator": EvaluatorConfig,
            "demonstrator": DemonstratorConfig, "up": UpConfig}  # fmt: skip


def test_every_service_reads_the_one_observation_variable(monkeypatch, capsys) -> None:
    monkeypatch.setenv(OBSERVATION_ENV, "learning_plan")
    for command, config in SERVICES.items():
        args = build_parser().parse_args([command])
        assert options_from_args(config, args, "NAVLEARN_X").observation == "learning_plan", command
        with pytest.raises(SystemExit):
            main([command, "--help"])
        assert f"[env {OBSERVATION_ENV}; default learning]" in " ".join(capsys.readouterr().out.split())


@pytest.mark.parametrize("command", list(SERVICES))
def test_an_unknown_observation_is_refused_naming_the_choices(command, capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        main([command, "--observation", "lidar"])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "'lidar'" in err and "learning_plan" in err, err


@pytest.mark.integration
@pytest.mark.timeout(600)
def test_an_actor_of_another_observation_than_its_learner_says_which_to_give(tmp_path) -> None:
    """The real processes: a learner in ``learning``, an actor started with ``learning_plan``; the
    actor refuses the learner's weights naming the flag, the learner refuses its transitions, and
    `navlearn status` shows which observation the learner takes."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with small_learner(endpoint, "obs", tmp_path / "ckpt") as learner_lines:
        argv = ["-m", "services.cli", "actor", "--connect", endpoint, "--run", "obs", "--id", "a1",
                "--envs", "1", "--batch-steps", "1", "--observation", "learning_plan"]  # fmt: skip
        actor, lines = start(argv)
        try:
            line = wait_for_line(lines, "ignoring weights", timeout=240)
            assert "observation.plan_length=False (this process has True)" in line, line
            assert "start it with --observation learning" in line, line
            line = wait_for_line(learner_lines, "transitions/a1: shape", timeout=120)
            dims = observation_dim(LEARNING_PLAN_NAV), observation_dim(LEARNING_NAV)
            assert "transitions.obs has dimension {} (accepted: 1 to {})".format(*dims) in line, line
            asked = ["status", "--connect", endpoint, "--run", "obs"]
            view = json.loads(navlearn(*asked, "--json").stdout)
            assert view["learner"]["observation"] == "learning", view["learner"]
            assert re.search(r"observation\s+\S\s+learning\s", navlearn(*asked).stdout)  # the table's row
        finally:
            assert stop(actor) == 0

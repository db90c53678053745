"""A user's own Gymnasium env (``--env``): naming and building it, NNQL's space rules, the evaluation
on it, and `navlearn up --env` through the real processes (learner, actor, evaluator) with tiny envs
defined here - Box and Dict observations - plus the refusals: an actor of another env than its
learner's, and an env with continuous actions."""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import free_port
from wire_helpers import start, stop, wait_for_line

from agents.evaluation.env_returns import evaluate_env, summarize_episodes
from agents.evaluation.policies import load_policy
from protocols.codec import decode, encode
from protocols.messages import OWN_WORLD, WeightsUpdate
from worlds.own_env import EnvConfig, EnvError, env_spaces, make_env, make_vector_env

REPO = Path(__file__).resolve().parents[1]

# The user's file: a corridor of 5 cells, start in the middle, actions 0 (left) / 1 (right), the goal
# at the right end (+1, terminated, is_success) and a pit at the left end (-1, terminated); 20 steps
# at most (truncated). Three observation spaces and one continuous-action variant of it.
TINY_ENVS = textwrap.dedent(
    '''
    import gymnasium as gym
    import numpy as np
    from gymnasium import spaces


    class Corridor(gym.Env):
        """A 5-cell corridor; observation in the shape the subclass says."""

        LENGTH, LIMIT = 5, 20

        def __init__(self, limit=LIMIT):
            self.limit = int(limit)
            self.action_space = spaces.Discrete(2)
            self.observation_space = spaces.Box(0.0, 1.0, (2, 3), np.float32)

        def observe(self):
            grid = np.zeros((2, 3), np.float32)
            grid[0, 0] = self.pos / (self.LENGTH - 1)
            grid[1, 2] = self.t / self.limit
            return grid

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            self.pos, self.t = 2, 0
            return self.observe(), {}

        def step(self, action):
            self.pos += 1 if int(action) == 1 else -1
            self.t += 1
            goal, pit = self.pos == self.LENGTH - 1, self.pos == 0
            reward = 1.0 if goal else -1.0 if pit else -0.01
            terminated = goal or pit
            truncated = not terminated and self.t >= self.limit
            info = {"is_success": goal} if terminated or truncated else {}
            return self.observe(), reward, terminated, truncated, info


    class DictCorridor(Corridor):
        def __init__(self, limit=Corridor.LIMIT):
            super().__init__(limit)
            self.observation_space = spaces.Dict(
                {"cell": spaces.Discrete(self.LENGTH), "time": spaces.Box(0.0, 1.0, (1,), np.float32)}
            )

        def observe(self):
            return {"cell": self.pos, "time": np.array([self.t / self.limit], np.float32)}


    class SteeredCorridor(Corridor):
        def __init__(self, limit=Corridor.LIMIT):
            super().__init__(limit)
            self.action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)


    def make_box(limit=Corridor.LIMIT):
        return Corridor(limit)


    class GridImage(gym.Env):
        """An 8x8 grid seen as an 8x8x3 uint8 image (an image by SB3's rule): channel 0 is the agent,
        channel 1 the goal; actions 0..3 move up, down, left, right; reaching the goal: +1, terminated,
        is_success; 16 steps at most."""

        SIZE, MOVES = 8, ((-1, 0), (1, 0), (0, -1), (0, 1))

        def __init__(self, limit=16):
            self.limit = int(limit)
            self.action_space = spaces.Discrete(4)
            self.observation_space = spaces.Box(0, 255, (self.SIZE, self.SIZE, 3), np.uint8)

        def observe(self):
            image = np.zeros((self.SIZE, self.SIZE, 3), np.uint8)
            image[self.pos[0], self.pos[1], 0] = image[self.goal[0], self.goal[1], 1] = 255
            return image

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            self.goal = np.array([self.SIZE - 1, self.SIZE - 1])
            self.pos, self.t = self.np_random.integers(0, self.SIZE - 1, 2), 0
            return self.observe(), {}

        def step(self, action):
            self.pos = np.clip(self.pos + self.MOVES[int(action)], 0, self.SIZE - 1)
            self.t += 1
            goal = bool((self.pos == self.goal).all())
            truncated = not goal and self.t >= self.limit
            info = {"is_success": goal} if goal or truncated else {}
            return self.observe(), 1.0 if goal else -0.01, goal, truncated, info
    '''
)


@pytest.fixture
def user_module(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    """The tiny envs as a user's module on the path (this process's and its subprocesses')."""
    name = f"tiny_envs_{os.getpid()}"
    (tmp_path / f"{name}.py").write_text(TINY_ENVS)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join([str(tmp_path), str(REPO), os.environ.get("PYTHONPATH", "")])
    )
    return name


def test_the_env_is_named_by_id_module_id_or_callable_and_bad_names_say_the_fix(user_module: str) -> None:
    assert env_spaces(EnvConfig(env="CartPole-v1")) == (4, 2)
    assert env_spaces(EnvConfig(env=f"{user_module}:make_box", env_kwargs='{"limit": 7}')) == (6, 2)
    assert make_env(EnvConfig(env=f"{user_module}:make_box", env_kwargs='{"limit": 7}')).unwrapped.limit == 7
    with pytest.raises(EnvError, match="not a registered Gymnasium id; give --env-module"):
        make_env(EnvConfig(env="NoSuchEnv-v0"))
    with pytest.raises(EnvError, match=r"Taxi-v2: not a registered Gymnasium id \(did you mean Taxi-v4\?\)"):
        make_env(EnvConfig(env="Taxi-v2"))
    with pytest.raises(EnvError, match="cannot import module 'no_such_module_xyz'"):
        make_env(EnvConfig(env="no_such_module_xyz:make"))
    with pytest.raises(EnvError, match=f"module '{user_module}' has no 'nothing'"):
        make_env(EnvConfig(env=f"{user_module}:nothing"))
    with pytest.raises(EnvError, match="not valid JSON"):
        EnvConfig(env="CartPole-v1", env_kwargs="{limit: 3}")
    with pytest.raises(EnvError, match="a JSON object is needed"):
        EnvConfig(env="CartPole-v1", env_kwargs="[3]")
    with pytest.raises(EnvError, match="give --env too"):
        EnvConfig(env_kwargs='{"a": 1}')
    with pytest.raises(EnvError, match=r"building it failed .*unexpected keyword"):
        make_env(EnvConfig(env=f"{user_module}:make_box", env_kwargs='{"bogus": 1}'))


def test_dict_observations_are_flattened_and_continuous_actions_refused_with_the_reason(
    user_module: str,
) -> None:
    env = make_env(EnvConfig(env=f"{user_module}:DictCorridor"))
    obs, _ = env.reset(seed=0)
    assert obs.shape == (6,) and obs[2] == 1.0  # one-hot cell 2 (of 5), then the time
    with pytest.raises(EnvError, match=r"NNQL learns one Q-value per discrete action.*discretise"):
        make_env(EnvConfig(env=f"{user_module}:SteeredCorridor"))
    with pytest.raises(EnvError, match="Box"):
        make_env(EnvConfig(env="Pendulum-v1"))


def test_signature_and_record_round_trip_and_name_kwargs() -> None:
    config = EnvConfig(env="CartPole-v1", env_kwargs='{"max_episode_steps": 50}')
    assert config.signature() == 'CartPole-v1 {"max_episode_steps":50}'
    assert EnvConfig.from_record(config.record()).signature() == config.signature()
    assert EnvConfig().signature() == OWN_WORLD and EnvConfig().record() is None
    long = EnvConfig(env="CartPole-v1", env_kwargs=json.dumps({"x" * 300: 1}))
    assert len(long.signature()) <= 200 and "kwargs-sha1:" in long.signature()
    assert config.flags() == ["--env", "CartPole-v1", "--env-kwargs", '{"max_episode_steps": 50}']
    update = decode(encode(WeightsUpdate(model="nnql", version=1, tensors={}, env=config.signature())))
    assert update.env == config.signature() and "env" not in update.architecture


def test_vector_env_keeps_terminal_observations_and_truncation_apart(user_module: str) -> None:
    env = make_vector_env(EnvConfig(env=f"{user_module}:make_box", env_kwargs='{"limit": 3}'), 2)
    env.reset(seed=0)
    # copy 0 walks right: goal after 2 steps (terminated); copy 1 bounces: truncated at step 3
    for actions in ([1, 1], [1, 0]):
        _, _, terminated, truncated, info = env.step(np.array(actions))
    assert terminated.tolist() == [True, False] and "final_obs" in info
    assert info["final_obs"][0][0] == 1.0  # the terminal observation (flattened), at the goal
    _, _, terminated, truncated, info = env.step(np.array([1, 1]))
    assert truncated.tolist() == [False, True] and terminated.tolist() == [False, False]
    assert info["final_info"]["_is_success"][1] and not info["final_info"]["is_success"][1]
    env.close()


def test_evaluation_reports_return_interval_success_and_length(user_module: str) -> None:
    config = EnvConfig(env=f"{user_module}:make_box")
    right = evaluate_env(lambda obs: np.ones(len(obs), np.int64), config, episodes=7, num_envs=3)
    metrics = right[config.env]
    assert metrics["episodes"] == 7 and metrics["length"] == 2.0
    assert metrics["success"]["value"] == 1.0 and abs(metrics["return"]["mean"] - 0.99) < 1e-6
    left = evaluate_env(lambda obs: np.zeros(len(obs), np.int64), config, episodes=5)[config.env]
    assert left["success"]["value"] == 0.0 and left["return"]["mean"] == pytest.approx(-1.01)
    m = summarize_episodes([1.0, 3.0], [2, 4], [None, None], threshold=2.5)
    assert "success" not in m and m["solved"] is False and m["return"]["low"] < 2.0 < m["return"]["high"]


def navlearn(*argv: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "services.cli", *argv],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=REPO,
    )


@pytest.mark.parametrize("factory", ["make_box", "DictCorridor"])
def test_up_trains_and_evaluates_a_users_env_through_the_real_processes(
    user_module: str, tmp_path: Path, factory: str
) -> None:
    out = tmp_path / "run"
    done = navlearn(
        "up", "--env", f"{user_module}:{factory}", "--env-kwargs", '{"limit": 12}', "--run", f"tiny{factory}",
        "--out", str(out), "--actors", "1", "--envs", "4", "--duration", "8", "--eval-episodes", "10",
        "--hidden-sizes", "16", "--learning-starts", "200", "--checkpoint-every", "30",
    )  # fmt: skip
    assert done.returncode == 0, (done.stdout, done.stderr)
    assert f"env {user_module}:{factory}" in done.stdout and "over 10 episodes" in done.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["final_version"] > 0
    last = summary["last_evaluation"]["metrics"][f"{user_module}:{factory}"]
    assert last["episodes"] == 10 and set(last) >= {"return", "length", "success"}
    assert (out / "eval" / "learning_curve.png").stat().st_size > 0
    policy = load_policy(out / "policy")
    assert policy.env == {"id": f"{user_module}:{factory}", "kwargs": {"limit": 12}, "module": ""}
    assert policy.obs_dim == 6
    shown = navlearn("evaluate", "--policy", str(out / "policy"), "--episodes", "4")
    assert shown.returncode == 0, shown.stderr
    assert f"{user_module}:{factory}: return" in shown.stdout and "over 4 episodes" in shown.stdout


def test_up_learns_an_image_env_with_the_cnn_through_the_real_processes(
    user_module: str, tmp_path: Path
) -> None:
    """An env observing an 8x8x3 uint8 image: the learner builds the CNN (--network cnn: auto would
    flatten an image this small into the MLP), the actors and
    the evaluator run it from the weights' architecture, and the saved policy evaluates alone."""
    out, name = tmp_path / "run", f"{user_module}:GridImage"
    done = navlearn(
        "up", "--env", name, "--run", "tinyimage", "--out", str(out), "--actors", "1", "--envs", "4",
        "--network", "cnn", "--duration", "8", "--eval-episodes", "10", "--hidden-sizes", "16",
        "--learning-starts", "200", "--checkpoint-every", "30",
    )  # fmt: skip
    assert done.returncode == 0, (done.stdout, done.stderr)
    learner_log = (out / "logs" / "learner.log").read_text()
    assert "192 inputs (image 8x8x3), 4 actions, network cnn" in learner_log, learner_log
    last = json.loads((out / "summary.json").read_text())["last_evaluation"]["metrics"][name]
    assert last["episodes"] == 10 and "success" in last
    saved = json.loads((out / "policy" / "config.json").read_text())
    image = saved["architecture"]["image"]
    assert image["shape"] == [8, 8, 3] and image["channels_last"] and image["pool"] == 2
    assert load_policy(out / "policy").obs_dim == 192
    shown = navlearn("evaluate", "--policy", str(out / "policy"), "--episodes", "4")
    assert shown.returncode == 0, shown.stderr
    assert f"{name}: return" in shown.stdout and "over 4 episodes" in shown.stdout
    box = f"{user_module}:make_box"
    refused = navlearn("up", "--env", box, "--network", "cnn", "--out", str(tmp_path / "no"))
    assert refused.returncode == 2 and "--network cnn) needs an image observation" in refused.stderr


def test_an_actor_of_another_env_is_refused_by_the_learner_naming_both(
    user_module: str, tmp_path: Path
) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    mine, theirs = f"{user_module}:make_box", f"{user_module}:DictCorridor"
    learner, lines = start(
        [
            "-m",
            "services.cli",
            "learner",
            "--listen",
            endpoint,
            "--run",
            "mixed",
            "--env",
            mine,
            "--checkpoint-dir",
            "",
            "--hidden-sizes",
            "16",
        ]
    )
    actor = None
    try:
        wait_for_line(lines, "learner learner up", timeout=120)
        actor, _ = start(
            [
                "-m",
                "services.cli",
                "actor",
                "--connect",
                endpoint,
                "--run",
                "mixed",
                "--id",
                "other",
                "--env",
                theirs,
                "--envs",
                "2",
                "--batch-steps",
                "4",
            ]
        )
        line = wait_for_line(lines, "refused transitions from actor other", timeout=60)
        assert f"it runs env '{theirs}', this learner trains on env '{mine}'" in line, line
    finally:
        if actor is not None:
            stop(actor)
        stop(learner, timeout=30)


def test_a_continuous_env_is_refused_before_anything_starts(user_module: str, tmp_path: Path) -> None:
    for command in (["up", "--out", str(tmp_path / "never")], ["actor"], ["learner", "--checkpoint-dir", ""]):
        done = navlearn(*command, "--env", f"{user_module}:SteeredCorridor", timeout=60)
        assert done.returncode == 2, (command, done.stdout, done.stderr)
        assert "NNQL learns one Q-value per discrete action" in done.stderr, done.stderr
    assert not (tmp_path / "never").exists()


def test_the_documented_example_env_passes_gymnasiums_checks_and_both_of_its_names_work() -> None:
    from gymnasium.utils.env_checker import check_env

    example = importlib.import_module("examples.own_env.warehouse")  # a user's file, not a package of ours
    check_env(example.WarehouseAisle(length=6), skip_render_check=True)
    by_class = EnvConfig(env="examples.own_env.warehouse:WarehouseAisle", env_kwargs='{"length": 6}')
    by_id = EnvConfig(env_module="examples.own_env.warehouse", env="navlearn-example/WarehouseAisle-v0")
    assert env_spaces(by_class) == env_spaces(by_id) == (4, 3)
    forward = evaluate_env(lambda obs: np.ones(len(obs), np.int64), by_class, episodes=8)[by_class.env]
    assert 0.0 <= forward["success"]["value"] <= 1.0 and forward["length"] <= 24


def test_train_local_trains_on_a_users_env_and_saves_a_policy_that_records_it(
    user_module: str, tmp_path: Path
) -> None:
    out = tmp_path / "local"
    done = navlearn(
        "train", "--local", "--env", f"{user_module}:DictCorridor", "--steps", "1600", "--envs", "4",
        "--eval-every", "800", "--eval-episodes", "6", "--final-eval-episodes", "6", "--hidden-sizes", "16",
        "--no-progress", "--out", str(out),
    )  # fmt: skip
    assert done.returncode == 0, (done.stdout, done.stderr)
    assert f"{user_module}:DictCorridor: return" in done.stdout and "success" in done.stdout
    assert load_policy(out).env["id"] == f"{user_module}:DictCorridor"
    assert json.loads((out / "summary.json").read_text())["final_eval"]["episodes"] == 6


def test_a_checkpoint_of_another_env_is_refused_on_resume_naming_both() -> None:
    from agents.nnql.config import NNQLConfig
    from agents.nnql.learner import NNQLLearner

    config = NNQLConfig(hidden_sizes=(8,), replay_capacity=64, batch_size=4)
    saved = NNQLLearner(config, 4, 2)
    saved.env = EnvConfig(env="CartPole-v1").record()
    state = saved.state_dict()
    other = NNQLLearner(config, 4, 2)
    other.env = EnvConfig(env="CartPole-v1", env_kwargs='{"max_episode_steps": 50}').record()
    with pytest.raises(ValueError, match=r"trained on env CartPole-v1, this learner runs env CartPole-v1 \{"):
        other.load_state_dict(state)
    world = NNQLLearner(config, 4, 2)
    with pytest.raises(ValueError, match="runs navlearn's world: resume it with --env CartPole-v1"):
        world.load_state_dict(state)
    same = NNQLLearner(config, 4, 2)
    same.env = EnvConfig(env="CartPole-v1").record()
    same.load_state_dict(state)


def test_async_copies_step_like_sync_ones(user_module: str) -> None:
    config = EnvConfig(env=f"{user_module}:make_box", env_kwargs='{"limit": 3}')
    results = []
    for mode in ("sync", "async"):
        env = make_vector_env(EnvConfig(**{**config.__dict__, "env_vector": mode}), 2)
        try:
            steps = [env.reset(seed=3)[0]]
            for actions in ([1, 1], [1, 0], [0, 1]):
                obs, reward, terminated, truncated, _ = env.step(np.array(actions))
                steps += [obs, reward, terminated, truncated]
        finally:
            env.close()
        results.append(steps)
    for a, b in zip(*results, strict=True):
        np.testing.assert_array_equal(a, b)


def test_up_keeps_the_best_evaluated_version_as_its_policy_and_opts_out_with_no_keep_best(
    user_module: str, tmp_path: Path
) -> None:
    """Keep-best through the real processes: the saved policy is the version whose validation
    evaluation (seed 1) scored best, ties to the later, not the learner's last; its weights are the ones
    measured (they replay the recorded figures); --no-keep-best saves the last on the test seed."""
    from agents.evaluation.selection import VALIDATION_SEED, score

    name = f"{user_module}:make_box"
    common = ["--env", name, "--env-kwargs", '{"limit": 12}', "--actors", "1", "--envs", "4",
              "--eval-episodes", "10", "--hidden-sizes", "16", "--learning-starts", "200",
              "--checkpoint-every", "30"]  # fmt: skip
    out = tmp_path / "kept"
    done = navlearn("up", *common, "--run", "keptbest", "--out", str(out), "--duration", "10")
    assert done.returncode == 0, (done.stdout, done.stderr)
    points = [json.loads(x) for x in (out / "eval" / "evaluations.jsonl").read_text().splitlines()]
    assert len(points) >= 2, points
    best = max(points, key=lambda p: (score(p["metrics"]), p["time"]))  # ties: the later version
    summary = json.loads((out / "summary.json").read_text())
    saved = json.loads((out / "policy" / "config.json").read_text())
    assert summary["eval_seed"] == VALIDATION_SEED and saved["kept"]["eval_seed"] == VALIDATION_SEED
    assert (
        saved["version"] == summary["policy_version"] == summary["kept"]["version"] == best["policy_version"]
    )
    assert saved["kept"]["score"] == list(score(best["metrics"]))
    if score(points[-1]["metrics"]) < score(best["metrics"]):  # the learner's last lost: not what is saved
        assert saved["version"] != points[-1]["policy_version"]
    assert saved["nnql_config"]["hidden_sizes"] == [16] and saved["env"]["id"] == name
    replayed = evaluate_env(
        load_policy(out / "policy"), EnvConfig.from_record(saved["env"]), 10, VALIDATION_SEED
    )
    assert replayed[name]["return"]["mean"] == pytest.approx(best["metrics"][name]["return"]["mean"])
    assert f"policy: version {best['policy_version']}, the best the evaluator measured" in done.stdout

    last = tmp_path / "last"
    done = navlearn(
        "up", *common, "--run", "lastone", "--out", str(last), "--duration", "4", "--no-keep-best"
    )
    assert done.returncode == 0, (done.stdout, done.stderr)
    summary = json.loads((last / "summary.json").read_text())
    assert summary["kept"] is None and summary["eval_seed"] == 0
    assert (
        summary["policy_version"] == summary["final_version"] and not (last / "eval" / "best-policy").exists()
    )
    assert f"policy: the learner's last version {summary['final_version']}" in done.stdout


def test_up_gives_its_processes_the_env_config_as_a_file_and_flags_win_over_it(tmp_path: Path) -> None:
    """`up` hands the run's EnvConfig to the learner, the actors and the evaluator as a file (no env
    flags rebuilt from it); each reads back the very config, kwargs with awkward JSON included."""
    from agents.nnql.config import NNQLConfig
    from services.cli import build_parser
    from services.common.env_options import env_from_args
    from services.ops.up import Up
    from services.ops.up_config import UpConfig

    env = EnvConfig(env="CartPole-v1", env_kwargs='{"max_episode_steps": 50, "note": "a b,\\"c\\""}',
                    env_vector="async")  # fmt: skip
    up = Up(UpConfig(out=str(tmp_path / "run"), actors=2), NNQLConfig(), env)
    started: dict[str, list[str]] = {}
    up._spawn = lambda name, argv, _env: started.__setitem__(name, argv)
    up.start()
    assert set(started) == {"learner", "actor-1", "actor-2", "evaluator"}
    for name, argv in started.items():
        assert "--env" not in argv and "--env-kwargs" not in argv and "--env-vector" not in argv, (name, argv)
        assert argv[argv.index("--env-config") + 1] == str(tmp_path / "run" / "env.json"), (name, argv)
        args = build_parser().parse_args(argv)
        assert env_from_args(args) == env, name
    argv = [*started["actor-1"], "--env-kwargs", '{"max_episode_steps": 9}']
    assert env_from_args(build_parser().parse_args(argv)).kwargs == {"max_episode_steps": 9}  # the flag wins
    (tmp_path / "bad.json").write_text('{"env": "CartPole-v1", "kwargs": {}}')
    with pytest.raises(ValueError, match=r"bad.json: unknown EnvConfig field\(s\) \['kwargs'\]"):
        env_from_args(build_parser().parse_args(["evaluator", "--env-config", str(tmp_path / "bad.json")]))

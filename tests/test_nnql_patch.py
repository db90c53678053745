"""The Q-network with a CNN over the own-map patch (variant F): split, forward, files, options."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import torch

from agents.evaluation.policies import load_policy
from agents.evaluation.runner import evaluate, make_eval_set
from agents.forward import TorchForward
from agents.nirl.config import NIRLConfig
from agents.nnql.action_local import LocalQNetwork
from agents.nnql.config import LocalConfig, NNQLConfig, PatchConfig
from agents.nnql.learner import NNQLLearner
from agents.nnql.patch_network import PatchQNetwork, goal_images
from agents.nnql.policy import NNQLPolicy
from agents.nnql.q_networks import build_q_network
from services.cli import main
from worlds.config import NavConfig, ObservationConfig, SensorConfig, observation_settings
from worlds.perception import frame_dim, frame_layout, observation_dim
from worlds.vector_env import NavigationVectorEnv

BASE = {"hidden_sizes": (16,), "batch_size": 8, "learning_starts": 8, "seed": 3}
CNN = PatchConfig(channels=(4, 4), strides=(1, 1))
SMALL = NNQLConfig(**BASE, network="patch", patch=CNN)


def cnn(**fields) -> NNQLConfig:
    """SMALL with these PatchConfig fields."""
    return replace(SMALL, patch=replace(CNN, **fields))


def patch_nav(size: int = 6, **observation) -> NavConfig:
    return NavConfig(sensors=SensorConfig(n_beams=8, n_rays=16),
                     observation=ObservationConfig(patch_size=size, **observation))  # fmt: skip


def learner_for(nav: NavConfig, config: NNQLConfig = SMALL) -> NNQLLearner:
    return NNQLLearner(
        config, observation_dim(nav), nav.robot.n_actions, observation=observation_settings(nav)
    )


def env_observations(nav: NavConfig, n: int = 6, steps: int = 5) -> np.ndarray:
    env = NavigationVectorEnv(n, config=nav, seed=1)
    obs, _ = env.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(steps):
        obs, *_ = env.step(rng.integers(0, nav.robot.n_actions, size=n))
    env.close()
    return obs


def test_split_puts_each_frames_patch_values_in_their_channel_and_cell():
    """Observation value i = i: every image pixel and every vector entry says where it came from."""
    nav = patch_nav(5, frame_stack=2, previous_action=True, subgoal="own_map")
    net = build_q_network(SMALL, observation_dim(nav), 5, observation_settings(nav))
    assert isinstance(net, PatchQNetwork)
    fdim, (start, stop) = frame_dim(nav), frame_layout(nav)["patch"]
    assert stop == fdim  # the patch closes the frame: readings, goal, subgoal, previous action, patch
    obs = torch.arange(observation_dim(nav), dtype=torch.float32)
    images, rest = net.split(obs.unsqueeze(0))
    assert images.shape == (1, 4, 5, 5) and rest.shape == (1, 2 * start)
    for frame in range(2):
        for channel in range(2):  # occupancy, visits: interleaved per cell in the observation
            for u, v in [(0, 0), (0, 4), (3, 1), (4, 4)]:
                want = frame * fdim + start + 2 * (u * 5 + v) + channel
                assert images[0, 2 * frame + channel, u, v].item() == want
    # the rest: the first frame's non-patch inputs, then the second's, in order
    assert rest[0].tolist() == [*range(start), *range(fdim, fdim + start)]


def test_split_of_a_real_observation_separates_map_from_the_other_inputs():
    nav = patch_nav(6, subgoal="own_map")
    obs = env_observations(nav)
    net = build_q_network(SMALL, obs.shape[1], 5, observation_settings(nav))
    images, rest = net.split(torch.as_tensor(obs))
    start = frame_layout(nav)["patch"][0]
    np.testing.assert_array_equal(rest.numpy(), obs[:, :start])
    occupancy, visits = images[:, 0].numpy(), images[:, 1].numpy()
    assert set(np.unique(occupancy)) <= {0.0, 0.5, 1.0} and (occupancy == 0.0).any()
    assert ((visits >= 0) & (visits < 1)).all() and (visits > 0).any(axis=(1, 2)).all()  # it has been here


def test_network_picks_the_variant_and_auto_picks_by_the_observation():
    plain, nav = patch_nav(0), patch_nav(6)
    auto = NNQLConfig(**BASE)
    net = build_q_network(auto, observation_dim(plain), 5, observation_settings(plain))
    assert isinstance(net, LocalQNetwork) and net.local.spec["window"] == LocalConfig().window
    assert "local" not in build_q_network(auto, 30, 5).architecture  # no navlearn observation: the MLP
    mlp = replace(auto, network="mlp")
    net = build_q_network(mlp, observation_dim(nav), 5, observation_settings(nav))
    assert not isinstance(net, PatchQNetwork | LocalQNetwork) and "patch" not in net.architecture
    auto_cnn = build_q_network(
        replace(SMALL, network="auto"), observation_dim(nav), 5, observation_settings(nav)
    )
    assert isinstance(auto_cnn, PatchQNetwork) and "local" not in auto_cnn.architecture
    assert learner_for(plain, auto).config.network == "local"  # the learner records what it built


def test_actor_forward_equals_the_learners_after_updates():
    nav = patch_nav(6)
    learner = learner_for(nav)
    obs = env_observations(nav, n=8)
    rng = np.random.default_rng(1)
    for _ in range(3):
        learner.add({
            "obs": obs, "action": rng.integers(0, 5, 8), "reward": rng.normal(size=8).astype(np.float32),
            "next_obs": obs[::-1].copy(), "terminated": np.zeros(8, bool), "truncated": np.zeros(8, bool),
        })  # fmt: skip
    learner.update(4)
    # the actor's policy is built from what travels on the wire: weights and a JSON architecture
    wire = json.loads(json.dumps(learner.architecture))
    policy = NNQLPolicy(learner.get_weights(), wire, version=learner.version)
    assert isinstance(policy.forward, TorchForward)
    np.testing.assert_allclose(policy.q_values(obs), learner.q_values(obs), rtol=1e-6, atol=1e-6)
    before = policy.q_values(obs)
    learner.update(2)
    policy.set_weights(learner.get_weights(), learner.version)
    assert not np.allclose(policy.q_values(obs), before)
    np.testing.assert_allclose(policy.q_values(obs), learner.q_values(obs), rtol=1e-6, atol=1e-6)


def test_saved_policy_records_the_cnn_and_evaluates_identically_after_reload(tmp_path):
    nav = patch_nav(6)
    learner = learner_for(nav)
    learner.save_policy(tmp_path / "p")
    config = json.loads((tmp_path / "p" / "config.json").read_text())
    patch = config["architecture"]["patch"]
    assert patch["size"] == 6 and patch["channels"] == [4, 4] and patch["start"] == 11
    assert config["observation"]["observation.patch_size"] == 6
    episodes = make_eval_set("unseen", 6, seed=2)
    runs = [
        evaluate(learner.policy(), episodes, config=nav),
        evaluate(NNQLPolicy.load(tmp_path / "p"), episodes, config=nav),
        evaluate(load_policy(tmp_path / "p"), episodes),  # `navlearn evaluate`'s loader
    ]
    traces = [[(e.outcome, e.steps, e.path_length) for e in r.episodes["unseen"]] for r in runs]
    assert traces[0] == traces[1] == traces[2]


def test_bad_values_raise_value_errors_naming_the_field():
    with pytest.raises(ValueError, match="channels"):
        PatchConfig(channels=(8, 0))
    with pytest.raises(ValueError, match="strides"):
        PatchConfig(strides=(1,))
    with pytest.raises(ValueError, match="kernel_sizes"):
        PatchConfig(kernel_sizes=())
    with pytest.raises(ValueError, match="network"):
        NNQLConfig(network="conv")
    with pytest.raises(ValueError, match="window"):
        LocalConfig(window=0)
    with pytest.raises(ValueError, match="patch_size"):
        ObservationConfig(patch_size=-1)
    net = PatchQNetwork({"obs_dim": 83, "n_actions": 5, "hidden_sizes": [8], "activation": "relu",
                         "patch": {"size": 6, "start": 11, "frame_dim": 83, "frames": 1, "channels": [4],
                                   "kernel_sizes": [3], "strides": [1]}})  # fmt: skip
    with pytest.raises(ValueError, match="patch"):
        PatchQNetwork({**net.architecture, "obs_dim": 84})
    with pytest.raises(ValueError, match="too small"):  # default CNN: 3x3 stride 2, then 3x3
        build_q_network(NNQLConfig(network="patch"), 43, 5, observation_settings(patch_nav(4)))
    weights = {k: v.numpy() for k, v in net.state_dict().items()}
    weights["cnn.0.weight"] = weights["cnn.0.weight"][:2]
    with pytest.raises(ValueError, match="do not fit"):
        NNQLPolicy(weights, net.architecture)


def test_train_local_cli_patch_option(tmp_path, capsys):
    assert main(["train", "--local", "--patch-size", "-2"]) == 2
    assert "patch_size" in capsys.readouterr().err
    assert main(["train", "--local", "--patch-goal"]) == 2
    assert "add --network patch and --patch-size" in capsys.readouterr().err
    assert main(["train", "--local", "--network", "patch"]) == 2
    assert "observation.patch_size > 0" in capsys.readouterr().err
    assert main(["train", "--local", "--patch-size", "8", "--local-window", "2"]) == 2  # auto: the CNN
    assert "add --network local" in capsys.readouterr().err
    out = tmp_path / "f"
    argv = ["train", "--local", "--patch-size", "8", "--subgoal", "none", "--steps", "600", "--envs", "4",
            "--out", str(out), "--eval-every", "0", "--final-eval-episodes", "0", "--hidden-sizes", "16",
            "--no-progress", "--patch-goal", "--patch-embed", "8", "--patch-window", "2"]  # fmt: skip
    assert main(argv) == 0
    config = json.loads((out / "config.json").read_text())
    assert config["architecture"]["patch"]["size"] == 8
    patch = config["architecture"]["patch"]
    assert patch["embed"] == 8 and patch["goal"]["at"] == 24  # the goal part follows the 24 sector readings
    assert config["observation"]["observation.subgoal"] == "none"
    assert config["nnql_config"]["network"] == "patch"  # auto, as built on this observation
    assert config["architecture"]["local"]["window"] == 2 and config["nnql_config"]["patch"]["window"] == 2


def test_an_actor_process_runs_a_cnn_policy_on_one_torch_thread(tmp_path):
    """Loading a CNN policy brings torch in (MLP actors never do); it then runs on one thread."""
    import subprocess
    import sys

    learner_for(patch_nav(6)).save_policy(tmp_path / "p")
    script = (
        "import sys\n"
        "from agents.nnql.policy import NNQLPolicy\n"
        "assert 'torch' not in sys.modules\n"
        f"policy = NNQLPolicy.load({str(tmp_path / 'p')!r})\n"
        "import torch\n"
        "print(torch.get_num_threads())\n"
    )
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split()[-1] == "1"


def test_world_show_draws_the_patch(tmp_path, capsys):
    assert main(["world", "show", "--patch", "-1"]) == 2
    assert "--patch" in capsys.readouterr().err
    out = tmp_path / "w.png"
    assert main(["world", "show", "--learning", "--patch", "8", "--steps", "5", "--out", str(out)]) == 0
    assert out.stat().st_size > 0


def assert_travels_with_the_policy(learner: NNQLLearner, obs: np.ndarray, tmp_path) -> None:
    """The actor's forward (built from the wire's JSON architecture) and a saved-then-loaded policy give
    the learner's Q-values."""
    wire = json.loads(json.dumps(learner.architecture))
    policies = [NNQLPolicy(learner.get_weights(), wire, version=learner.version)]
    learner.save_policy(tmp_path / "p")
    policies.append(NNQLPolicy.load(tmp_path / "p"))
    for policy in policies:
        np.testing.assert_allclose(policy.q_values(obs), learner.q_values(obs), rtol=1e-6, atol=1e-6)


def test_goal_images_put_the_goal_where_the_patch_samples_it():
    """PatchConfig.goal: a goal 3 m ahead lies between the centres of cells u = 10 and 11 (2.5 m, 3.5 m ahead)
    and v = 7, 8 (0.5 m right, 0.5 m left) of a 16x16 patch of 1 m cells; 6 m left at v = 13.5; a far
    goal is moved along its bearing onto the border; each image holds the goal's unit mass."""
    max_range = 6.0
    goals = torch.tensor([
        [3 / (3 + max_range), 0.0, 1.0],  # 3 m straight ahead (left, forward unit components)
        [0.5, 1.0, 0.0],  # 6 m to the left
        [0.9, 0.6, 0.8],  # 54 m away: forward 43.2, left 32.4 -> the front border
    ])  # fmt: skip
    images = goal_images(goals, 16, max_range)
    assert images.shape == (3, 16, 16)
    np.testing.assert_allclose(images.sum(dim=(1, 2)).numpy(), 1.0, rtol=1e-6)
    for k, cells in enumerate([
        {(10, 7): 0.25, (10, 8): 0.25, (11, 7): 0.25, (11, 8): 0.25},
        {(7, 13): 0.25, (7, 14): 0.25, (8, 13): 0.25, (8, 14): 0.25},
        {(15, 13): 0.875, (15, 14): 0.125},  # u on the border 15, v = 7.5 + 32.4 * 7.5 / 43.2
    ]):  # fmt: skip
        got = {(u, v): round(images[k, u, v].item(), 6) for u, v in images[k].nonzero().tolist()}
        assert got == cells


def test_patch_goal_adds_each_frames_goal_as_a_channel_and_travels_with_the_policy(tmp_path):
    nav = patch_nav(6, frame_stack=2)
    config = cnn(goal=True)
    learner = learner_for(nav, config)
    net = learner.network
    assert isinstance(net, PatchQNetwork) and net.architecture["patch"]["goal"] == {"at": 8, "max_range": 6.0}
    obs = env_observations(nav, n=4)
    images = net.split(torch.as_tensor(obs))[0]
    assert images.shape == (4, 6, 6, 6)  # occupancy, visits of 2 frames, then the 2 frames' goals
    fdim, at = frame_dim(nav), frame_layout(nav)["goal"][0]
    for frame in range(2):
        goal = torch.as_tensor(obs[:, frame * fdim + at : frame * fdim + at + 3])
        torch.testing.assert_close(images[:, 4 + frame], goal_images(goal, 6, 6.0))
    without = build_q_network(SMALL, observation_dim(nav), 5, observation_settings(nav))
    assert "goal" not in without.architecture["patch"]
    assert without.split(torch.as_tensor(obs))[0].shape[1] == 4
    assert_travels_with_the_policy(learner, obs, tmp_path)


def test_the_patch_network_or_its_settings_without_a_patch_are_clear_errors():
    plain = patch_nav(0)
    with pytest.raises(ValueError, match=r"network='patch'.*patch_size"):
        build_q_network(cnn(goal=True), observation_dim(plain), 5, observation_settings(plain))
    embed = replace(cnn(embed=8), network="auto")  # auto builds the action-local branch here
    with pytest.raises(ValueError, match=r"embed=8.*builds 'local'.*--network patch and --patch-size"):
        build_q_network(embed, observation_dim(plain), 5, observation_settings(plain))


def test_cnn_embed_maps_the_cnn_features_before_the_head_and_travels_with_the_policy(tmp_path):
    nav = patch_nav(6)
    learner = learner_for(nav, cnn(embed=5))
    net = learner.network
    assert (
        net.architecture["patch"]["embed"] == 5
        and net.head[0].in_features == 5 + frame_layout(nav)["patch"][0]
    )
    obs = env_observations(nav, n=4)
    assert_travels_with_the_policy(learner, obs, tmp_path)
    with pytest.raises(ValueError, match="embed"):
        PatchConfig(embed=-1)


def test_action_local_sees_each_actions_view_the_same_way_whichever_action_it_is(tmp_path):
    """The action-local branch beside the CNN (PatchConfig.window): with 8 readings 45 degrees apart (the
    first behind the robot), the actions' turns
    -90..90 degrees face readings 2..6; action 4 (90 degrees left) seeing the readings and goal of an
    observation is action 2 (straight on) seeing them turned 90 degrees right: the same branch output."""
    nav = patch_nav(6)
    learner = learner_for(nav, cnn(window=1))
    local = learner.network.local
    assert local.spec["headings"] == [2, 3, 4, 5, 6] and local.spec["goal_at"] == 8
    assert local.index.tolist() == [[1, 2, 3], [2, 3, 4], [3, 4, 5], [4, 5, 6], [5, 6, 7]]
    obs = torch.as_tensor(env_observations(nav, n=4))
    turned = obs.clone()
    turned[:, :8] = obs[:, :8].roll(-2, dims=1)  # reading k of `turned` is reading k + 2 of obs
    left, forward = obs[:, 9], obs[:, 10]  # bearing b -> b - 90 degrees
    turned[:, 9], turned[:, 10] = -forward, left
    with torch.no_grad():
        torch.testing.assert_close(local(turned)[:, 2], local(obs)[:, 4])
        torch.testing.assert_close(local(turned)[:, 0], local(obs)[:, 2])
        assert not torch.allclose(local(obs)[:, 2], local(obs)[:, 4])
        plain = learner.network.head(torch.cat([learner.network.cnn(learner.network.split(obs)[0]),
                                                learner.network.split(obs)[1]], dim=-1))  # fmt: skip
        torch.testing.assert_close(learner.network(obs), plain + local(obs))
    assert_travels_with_the_policy(learner, obs.numpy(), tmp_path)


def test_action_local_bad_values_are_clear_errors():
    with pytest.raises(ValueError, match=r"PatchConfig\.window=-1"):
        PatchConfig(window=-1)
    nav = patch_nav(6)
    with pytest.raises(ValueError, match=r"window 4.*window <= 3"):  # 9 readings of 8
        build_q_network(cnn(window=4), observation_dim(nav), 5, observation_settings(nav))
    plain = patch_nav(0)
    local = NNQLConfig(**BASE, network="local", local=LocalConfig(window=1))
    with pytest.raises(ValueError, match=r"network='local'.*observation"):  # no settings: no layout
        build_q_network(local, observation_dim(plain), 5)
    too_wide = replace(local, local=LocalConfig(window=4))
    with pytest.raises(ValueError, match=r"window 4.*window <= 3"):
        build_q_network(too_wide, observation_dim(plain), 5, observation_settings(plain))
    with pytest.raises(ValueError, match="does not fit frames"):  # a frame of 12 in 13 features
        LocalQNetwork({"obs_dim": 13, "n_actions": 5, "hidden_sizes": [4], "activation": "relu",
                       "frame_dim": 12, "local": {"readings_at": 0, "n_readings": 8, "goal_at": 8,
                                                  "headings": [2, 3, 4, 5, 6], "turns": [0.0] * 5,
                                                  "window": 1}})  # fmt: skip


@pytest.mark.parametrize("dueling", [False, True])
def test_action_local_without_a_patch_adds_the_branch_to_the_flat_mlp(tmp_path, dueling):
    """No patch (e.g. NIRL's learning_plan observation): Q = the flat MLP's (plain or dueling) + the
    branch over the newest frame's readings and goal, the same turned-view equivariance as with the
    patch; the policy runs that module in actors and files (torch forward), and NIRL builds it."""
    nav = patch_nav(0, frame_stack=2, subgoal="own_map", plan_length=True)
    config = NNQLConfig(**BASE, network="local", local=LocalConfig(window=1), dueling=dueling)
    learner = learner_for(nav, config)
    net = learner.network
    assert isinstance(net, LocalQNetwork) and net.architecture.get("dueling", False) is dueling
    assert net.frame_dim == frame_dim(nav) and net.local.spec["goal_at"] == 8
    obs = torch.as_tensor(env_observations(nav, n=4))
    with torch.no_grad():
        torch.testing.assert_close(net(obs), net.head(obs) + net.local(obs[:, : frame_dim(nav)]))
        older = obs.clone()
        older[:, frame_dim(nav) :] = 0.0  # the branch reads the newest frame only
        torch.testing.assert_close(net.local(obs[:, : frame_dim(nav)]), net.local(older[:, : frame_dim(nav)]))
        turned = obs[:, : frame_dim(nav)].clone()
        turned[:, :8] = obs[:, :8].roll(-2, dims=1)
        turned[:, 9], turned[:, 10] = -obs[:, 10], obs[:, 9]
        torch.testing.assert_close(net.local(turned)[:, 2], net.local(obs[:, : frame_dim(nav)])[:, 4])
    assert_travels_with_the_policy(learner, obs.numpy(), tmp_path)
    nirl = NIRLConfig(hidden_sizes=(16,), local=LocalConfig(window=1), dueling=dueling).nnql_config()
    assert isinstance(learner_for(nav, nirl).network, LocalQNetwork)  # network auto, on NIRL's observation
    assert learner_for(nav, nirl).network.local.spec["window"] == 1
    with pytest.raises(ValueError, match="window=-2"):
        NIRLConfig(local={"window": -2})


def test_a_config_saved_with_the_variant_fields_flat_rebuilds_the_network_it_trained(tmp_path):
    """Saved configs before ``network`` held q_network, action_local and cnn_*: each reads as the variant
    it built on its observation (pretrained/nnql's, and older ones whose shape git history keeps)."""
    from pathlib import Path

    saved = json.loads((Path(__file__).parents[1] / "pretrained" / "nnql" / "config.json").read_text())
    config = NNQLConfig.from_dict(saved["nnql_config"], saved["observation"])
    arch = saved["architecture"]
    rebuilt = build_q_network(config, arch["obs_dim"], arch["n_actions"], saved["observation"])
    assert config.network == "local" and rebuilt.architecture == arch
    flat = {k: v for k, v in SMALL.to_dict().items() if k not in ("network", "local", "patch")}
    cnn_fields = {"cnn_channels": [4, 4], "cnn_kernel_sizes": [3, 3], "cnn_strides": [1, 1], "cnn_goal": True}
    plain, nav = observation_settings(patch_nav(0)), observation_settings(patch_nav(6))
    old = {  # (flat fields, observation) -> the variant read
        "auto, no branch, no patch: the MLP": ({"q_network": "auto"}, plain, "mlp"),
        "auto with a patch: the CNN": ({"q_network": "auto", "action_local": 2, **cnn_fields}, nav, "patch"),
        "mlp with a patch: the MLP plus the branch": ({"q_network": "mlp", "action_local": 2}, nav, "local"),
    }
    for fields, observation, network in old.values():
        read = NNQLConfig.from_dict({**flat, **fields}, observation)
        assert read.network == network and build_q_network(read, 83, 5, observation) is not None
    read = NNQLConfig.from_dict({**flat, "q_network": "auto", "action_local": 2, **cnn_fields}, nav)
    assert read.patch == PatchConfig(channels=(4, 4), strides=(1, 1), goal=True, window=2)
    with pytest.raises(ValueError, match="both network and the flat variant fields"):
        NNQLConfig.from_dict({**SMALL.to_dict(), "action_local": 1})

"""The CNN over a Gymnasium env's image observation (network "cnn"): which spaces are images, the
convolutions the rule picks, the forward, the architecture round trip, "auto", refusals and resume."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from gymnasium import spaces

from agents.forward import TorchForward
from agents.nnql.config import ImageConfig, NNQLConfig
from agents.nnql.image_network import ImageQNetwork
from agents.nnql.learner import NNQLLearner
from agents.nnql.networks import DuelingQNetwork, QNetwork
from agents.nnql.policy import NNQLPolicy
from agents.nnql.q_networks import build_q_network, network_from_architecture
from worlds.config import LEARNING_NAV, observation_settings
from worlds.own_env import image_description

MINIGRID = spaces.Box(0, 255, (7, 7, 3), np.uint8)
IMAGE = image_description(MINIGRID)
SMALL = {
    "network": "cnn", "hidden_sizes": (16,), "batch_size": 8, "learning_starts": 8, "replay_capacity": 64,
    "seed": 2,
}  # fmt: skip


def image_obs(shape=(7, 7, 3), n: int = 6, seed: int = 0) -> np.ndarray:
    """Flat float observations of random uint8 images (what the wire carries)."""
    return np.random.default_rng(seed).integers(0, 256, (n, int(np.prod(shape)))).astype(np.float32)


def test_images_are_sb3s_three_dimensional_uint8_boxes_of_1_3_or_4_channels():
    assert IMAGE == {"shape": [7, 7, 3], "channels_last": True, "scale": 1 / 255}
    assert image_description(spaces.Box(0, 255, (4, 84, 84), np.uint8)) == {
        "shape": [4, 84, 84], "channels_last": False, "scale": 1 / 255,
    }  # fmt: skip
    assert image_description(spaces.Box(0, 255, (64, 48, 1), np.uint8))["channels_last"]
    not_images = [
        spaces.Box(0.0, 255.0, (7, 7, 3), np.float32),  # not uint8
        spaces.Box(0, 255, (7, 7), np.uint8),  # 2-D
        spaces.Box(0, 255, (7, 7, 5), np.uint8),  # 5 channels
        spaces.Box(0, 10, (7, 7, 3), np.uint8),  # high not 255
        spaces.Box(0, 255, (2, 7, 7, 3), np.uint8),  # 4-D
        spaces.Dict({"image": MINIGRID}),  # out of scope: learned flattened
        spaces.Discrete(4),
    ]
    assert [image_description(space) for space in not_images] == [None] * len(not_images)


def test_the_rule_gives_nature_from_36_px_and_the_minigrid_cnn_below():
    def conv(shape):
        return ImageConfig().convolutions({"shape": list(shape), "channels_last": True, "scale": 1 / 255})

    nature = conv((84, 84, 3))
    stack = [nature[key] for key in ("channels", "kernel_sizes", "strides")]
    assert stack == [[32, 64, 64], [8, 4, 3], [4, 2, 1]]
    assert nature["pool"] == 0 and nature["out"] == [7, 7] and conv((36, 48, 1))["out"] == [1, 2]
    minigrid = conv((7, 7, 3))
    stack = [minigrid[key] for key in ("channels", "kernel_sizes", "strides")]
    assert stack == [[16, 32, 64], [2, 2, 2], [1, 1, 1]]
    assert minigrid["pool"] == 2 and minigrid["out"] == [1, 1]  # rl-starter-files' 7x7 -> 1x1x64
    assert conv((5, 5, 3))["pool"] == 0 and conv((5, 5, 3))["out"] == [2, 2]  # the pool would leave 0x0
    assert conv((3, 3, 3))["channels"] == [16, 32]  # only the convolutions that fit
    assert conv((35, 35, 3))["channels"] == [16, 32, 64]
    given = ImageConfig(channels=(8,), kernel_sizes=(3,), strides=(2,)).convolutions(IMAGE)
    assert given == {"channels": [8], "kernel_sizes": [3], "strides": [2], "pool": 0, "out": [3, 3]}
    with pytest.raises(ValueError, match=r"--cnn-channels.*below 1x1"):
        ImageConfig(channels=(8,), kernel_sizes=(9,), strides=(1,)).convolutions(IMAGE)
    with pytest.raises(ValueError, match="give all three with one positive value per convolution"):
        ImageConfig(channels=(8, 8), kernel_sizes=(3,), strides=(1,))


@pytest.mark.parametrize("dueling", [False, True])
def test_the_network_reads_the_flat_vector_as_the_image_scaled_channels_first(dueling):
    config = NNQLConfig(**SMALL, dueling=dueling)
    network = build_q_network(config, 147, 7, None, IMAGE)
    assert isinstance(network, ImageQNetwork)
    assert isinstance(network.head, DuelingQNetwork if dueling else QNetwork)
    assert network.architecture["image"]["cnn_features"] == 64
    assert network.architecture.get("dueling", False) == dueling
    obs = torch.as_tensor(image_obs())
    assert network(obs).shape == (6, 7) and network(obs[0]).shape == (7,)
    # the pixel (row 2, column 5, channel 1) of the flat HWC vector is channel 1's (2, 5), scaled
    images = network.images(obs)
    assert images.shape == (6, 3, 7, 7)
    assert images[0, 1, 2, 5] == pytest.approx(float(obs[0, (2 * 7 + 5) * 3 + 1]) / 255)
    channels_first = ImageQNetwork({**network.architecture, "image": {
        **network.architecture["image"], "shape": [3, 7, 7], "channels_last": False}})  # fmt: skip
    assert channels_first.images(obs)[0, 1, 2, 5] == pytest.approx(float(obs[0, 49 + 2 * 7 + 5]) / 255)


@pytest.mark.parametrize("dueling", [False, True])
def test_the_architecture_rebuilds_the_same_network_on_the_wire_and_in_files(tmp_path, dueling):
    learner = NNQLLearner(NNQLConfig(**SMALL, dueling=dueling), 147, 7, image=IMAGE)
    obs = image_obs()
    rng = np.random.default_rng(1)
    for _ in range(2):
        learner.add({
            "obs": obs, "action": rng.integers(0, 7, 6), "reward": rng.normal(size=6).astype(np.float32),
            "next_obs": obs[::-1].copy(), "terminated": np.zeros(6, bool), "truncated": np.zeros(6, bool),
        })  # fmt: skip
    learner.update(3)
    wire = json.loads(json.dumps(learner.architecture))  # what a WeightsUpdate carries
    rebuilt = network_from_architecture(wire)
    rebuilt.load_state_dict({k: torch.as_tensor(v) for k, v in learner.get_weights().items()})
    q = rebuilt(torch.as_tensor(obs)).detach().numpy()
    np.testing.assert_allclose(q, learner.q_values(obs), atol=1e-6)
    policy = NNQLPolicy(learner.get_weights(), wire, version=learner.version)  # an actor's, the evaluator's
    assert isinstance(policy.forward, TorchForward)
    np.testing.assert_allclose(policy.q_values(obs), learner.q_values(obs), atol=1e-6)
    policy.save(tmp_path / "policy")
    loaded = NNQLPolicy.load(tmp_path / "policy")
    assert loaded.architecture == learner.architecture
    np.testing.assert_allclose(loaded.q_values(obs), learner.q_values(obs), atol=1e-6)


def test_auto_picks_the_cnn_for_a_frame_of_36_px_and_cnn_elsewhere_is_refused_naming_the_fix():
    auto = NNQLConfig()
    frame = image_description(spaces.Box(0, 255, (4, 84, 84), np.uint8))
    assert auto.resolved(None, frame).network == "cnn"  # a rendered frame: the CNN
    assert auto.resolved(None, IMAGE).network == "mlp"  # MiniGrid's 7x7 codes: flattened (measured better)
    side = image_description(spaces.Box(0, 255, (36, 40, 3), np.uint8))
    assert auto.resolved(None, side).network == "cnn"  # from AUTO_CNN_MIN_SIDE on
    assert auto.resolved(None, image_description(spaces.Box(0, 255, (35, 64, 3), np.uint8))).network == "mlp"
    assert NNQLConfig(network="cnn").resolved(None, IMAGE).network == "cnn"  # asked for: built
    assert auto.resolved(None).network == "mlp"  # another own env
    assert auto.resolved(observation_settings(LEARNING_NAV), None).network == "local"  # navlearn's world
    assert NNQLConfig(network="mlp").resolved(None, IMAGE).network == "mlp"  # flattened, as before
    assert isinstance(build_q_network(NNQLConfig(network="mlp"), 147, 7, None, IMAGE), DuelingQNetwork)
    with pytest.raises(ValueError, match=r"--network cnn\) needs an image observation.*--network mlp"):
        NNQLConfig(network="cnn").resolved(None)
    with pytest.raises(ValueError, match="navlearn's world observes range readings"):
        NNQLConfig(network="cnn").resolved(observation_settings(LEARNING_NAV))
    with pytest.raises(ValueError, match="add --network cnn with an --env whose observation is an image"):
        NNQLConfig(cnn=ImageConfig(channels=(8,), kernel_sizes=(2,), strides=(1,))).resolved(None)
    given = NNQLConfig(network="cnn", cnn=ImageConfig(channels=(8,), kernel_sizes=(3,), strides=(2,)))
    assert given.resolved(None, IMAGE).cnn.channels == (8,)


def test_configs_saved_before_the_cnn_still_load():
    saved = NNQLConfig().to_dict()
    del saved["cnn"]
    assert NNQLConfig.from_dict(saved) == NNQLConfig()
    config = NNQLConfig(network="cnn", cnn=ImageConfig(channels=(8,), kernel_sizes=(3,), strides=(2,)))
    assert NNQLConfig.from_dict(json.loads(json.dumps(config.to_dict()))) == config


def test_a_cnn_learner_resumes_from_its_checkpoint(tmp_path):
    learner = NNQLLearner(NNQLConfig(**SMALL), 147, 7, image=IMAGE)
    obs = image_obs(n=16)
    learner.add({
        "obs": obs, "action": np.arange(16) % 7, "reward": np.ones(16, np.float32),
        "next_obs": obs[::-1].copy(), "terminated": np.zeros(16, bool), "truncated": np.zeros(16, bool),
    })  # fmt: skip
    learner.update(2)
    path = learner.save_checkpoint(tmp_path / "ckpt")
    restored = NNQLLearner.from_checkpoint(path)
    assert restored.config.network == "cnn" and restored.architecture == learner.architecture
    np.testing.assert_array_equal(restored.q_values(obs), learner.q_values(obs))
    flat = NNQLLearner(NNQLConfig(**{**SMALL, "network": "mlp"}), 147, 7, image=IMAGE)  # not this checkpoint
    with pytest.raises(ValueError, match="checkpoint architecture"):
        flat.load_checkpoint(path)

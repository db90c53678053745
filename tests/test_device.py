"""--device cpu|cuda|auto: resolution, errors, and the learners (NNQL, NIRL) on each device (CUDA runs
only with a GPU)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from agents.device import resolve_device
from agents.nirl.config import NIRLConfig
from agents.nirl.learner import NIRLLearner
from agents.nnql.learner import NNQLLearner
from services.cli import main
from services.common.transport import ZenohSettings, free_port, open_session
from services.learner.nirl import NIRLTrainer
from tests.test_nirl_learner import SMALL, Episode, goal_seeking_steps
from tests.test_nnql_replay import N_ACTIONS, OBS_DIM, random_batch, small_config
from worlds.config import NavConfig

HAS_CUDA = torch.cuda.is_available()
needs_no_gpu = pytest.mark.skipif(HAS_CUDA, reason="a CUDA GPU is present: 'cuda' is not an error here")
needs_gpu = pytest.mark.skipif(
    not HAS_CUDA, reason="no CUDA GPU on this machine (torch.cuda.is_available() is False)"
)


def test_resolve_device():
    assert resolve_device("cpu") == torch.device("cpu")
    assert resolve_device("auto").type == ("cuda" if HAS_CUDA else "cpu")
    with pytest.raises(ValueError, match=r"device 'gpu': expected one of \('cpu', 'cuda', 'auto'\)"):
        resolve_device("gpu")


@needs_no_gpu
@pytest.mark.parametrize("name", ["cuda", "cuda:1"])
def test_cuda_without_gpu_is_one_clear_sentence(name):
    with pytest.raises(ValueError) as info:
        resolve_device(name)
    message = str(info.value)
    assert message.startswith(f"device {name!r}: torch sees no CUDA GPU on this machine")
    assert message.endswith("use --device cpu or auto.") and message.count(". ") == 0


@needs_no_gpu
def test_commands_refuse_cuda_without_gpu(capsys, tmp_path):
    argv = ["train", "--local", "--device", "cuda", "--steps", "10", "--out", str(tmp_path)]
    assert main(argv) == 2
    assert "navlearn train: device 'cuda': torch sees no CUDA GPU" in capsys.readouterr().err
    assert main(["learner", "--device", "cuda", "--checkpoint-dir", str(tmp_path)]) == 2
    assert "navlearn learner: device 'cuda': torch sees no CUDA GPU" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())  # refused before writing anything


def test_learner_option_rejects_unknown_device(capsys, tmp_path):
    assert main(["learner", "--device", "tpu", "--checkpoint-dir", str(tmp_path)]) == 2
    assert "LearnerConfig.device='tpu'" in capsys.readouterr().err


def check_learner_on(device: str) -> NNQLLearner:
    """Networks and optimiser state on ``device``, replay in host memory, checkpoint loads on the CPU."""
    learner = NNQLLearner(small_config(prioritized=True), OBS_DIM, N_ACTIONS, device=device)
    learner.add(random_batch(np.random.default_rng(0), 200))
    metrics = learner.update(4)
    assert np.isfinite(metrics["losses/td_loss"]) and learner.version == 4
    wanted = torch.device(device).type
    assert all(p.device.type == wanted for p in learner.loss.parameters())
    assert all(t.device.type == wanted for t in learner.lean.target_params)
    assert learner.replay.storage._storage.device.type == "cpu"
    obs = np.random.default_rng(1).random((3, OBS_DIM), dtype=np.float32)
    assert learner.q_values(obs).shape == (3, N_ACTIONS)
    return learner


def test_learner_on_cpu(tmp_path):
    learner = check_learner_on("cpu")
    restored = NNQLLearner.from_checkpoint(learner.save_checkpoint(tmp_path / "ckpt"))
    assert restored.update(2)["charts/version"] == 6


@needs_gpu
def test_learner_on_cuda_and_back(tmp_path):
    learner = check_learner_on("cuda")
    path = learner.save_checkpoint(tmp_path / "ckpt")
    on_cpu = NNQLLearner.from_checkpoint(path, device="cpu")
    for name, value in learner.get_weights().items():
        np.testing.assert_array_equal(on_cpu.get_weights()[name], value)
    assert on_cpu.update(2)["charts/version"] == 6


def nirl_learner(core: str, **kwargs) -> NIRLLearner:
    """A small NIRL learner holding 4 synthetic demonstrations and 300 random own steps."""
    schedule = {"warmstart_updates": 4, "q_updates": 3, "reward_updates": 2, "refine_start": 2}
    config = NIRLConfig(core=core, **schedule, **SMALL)
    learner = NIRLLearner(config, **kwargs)
    obs, actions = goal_seeking_steps(84, seed=0)
    learner.add_demos([Episode(obs[21 * i : 21 * (i + 1)], actions[21 * i : 21 * i + 20]) for i in range(4)])
    rng = np.random.default_rng(1)
    learner.add_experience({
        "obs": rng.random((300, learner.obs_dim), dtype=np.float32),
        "action": rng.integers(0, learner.n_actions, 300),
        "reward": np.zeros(300, np.float32),
        "next_obs": rng.random((300, learner.obs_dim), dtype=np.float32),
        "terminated": rng.random(300) < 0.1,
        "truncated": np.zeros(300, bool),
    })  # fmt: skip
    return learner


def train_nirl_briefly(learner: NIRLLearner) -> dict[str, float]:
    metrics = dict(learner.warm_start())
    metrics.update(learner.iterate())
    for _ in range(3):
        metrics.update(learner.update())
    return metrics


def nirl_weights(learner: NIRLLearner) -> dict[str, np.ndarray]:
    return {**learner.get_weights(), **{f"reward.{k}": v for k, v in learner.reward_weights().items()}}


@pytest.mark.parametrize("core", ["iq", "max_margin"])
def test_nirl_on_cpu_trains_as_without_the_argument(core, tmp_path):
    default = nirl_learner(core)
    default_metrics = train_nirl_briefly(default)
    learner = nirl_learner(core, device="cpu")
    assert train_nirl_briefly(learner) == default_metrics and learner.version == default.version == 10
    for name, value in nirl_weights(default).items():
        np.testing.assert_array_equal(nirl_weights(learner)[name], value)
    assert all(p.device.type == "cpu" for p in learner.reward.parameters())
    restored = nirl_learner(core, device="auto")
    restored.load_checkpoint(learner.save_checkpoint(tmp_path / "nirl"))
    for name, value in nirl_weights(learner).items():
        np.testing.assert_array_equal(nirl_weights(restored)[name], value)


@needs_no_gpu
def test_nirl_train_refuses_cuda_without_gpu(capsys, tmp_path):
    out = tmp_path / "run"
    argv = ["nirl", "train", "--demos", str(tmp_path / "demos"), "--device", "cuda", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err  # refused before the (missing) demonstrations are even read
    assert err.startswith("navlearn nirl train: device 'cuda': torch sees no CUDA GPU on this machine")
    assert err.count("\n") == 1 and not out.exists()
    argv = ["learner", "--nirl", "--device", "cuda", "--checkpoint-dir", str(tmp_path / "ckpt")]
    assert main(argv) == 2
    assert "navlearn learner: device 'cuda': torch sees no CUDA GPU" in capsys.readouterr().err


def test_nirl_train_rejects_unknown_device(capsys, tmp_path):
    assert main(["nirl", "train", "--demos", str(tmp_path), "--device", "tpu"]) == 2
    assert "navlearn nirl train: device 'tpu': expected one of" in capsys.readouterr().err


@needs_gpu
@pytest.mark.parametrize("core", ["iq", "sqil", "max_margin"])
def test_nirl_on_cuda_and_back(core, tmp_path):
    """Networks and optimisers on the GPU, buffers in host memory, weights as CPU numpy arrays,
    a CUDA checkpoint that loads and trains on the CPU."""
    learner = nirl_learner(core, device="cuda")
    metrics = train_nirl_briefly(learner)
    assert all(np.isfinite(v) for v in metrics.values()) and learner.version == 10
    assert all(p.device.type == "cuda" for p in learner.reward.parameters())
    assert all(p.device.type == "cuda" for p in learner.q.loss.parameters())
    assert learner.demos.storage._storage.device.type == "cpu"
    assert learner.experience.storage._storage.device.type == "cpu"
    assert all(isinstance(v, np.ndarray) for v in nirl_weights(learner).values())
    on_cpu = nirl_learner(core, device="cpu")
    on_cpu.load_checkpoint(learner.save_checkpoint(tmp_path / "nirl"))
    for name, value in nirl_weights(learner).items():
        np.testing.assert_array_equal(nirl_weights(on_cpu)[name], value)
    on_cpu.update()
    assert on_cpu.version == 11


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=needs_gpu)])
def test_learner_services_nirl_trainer_on_the_learners_device(device, tmp_path):
    """The learner service's NIRL trainer (services.learner.run passes it the learner's --device):
    networks on the device, the service's shared buffers in host memory, broadcasts from numpy."""
    source = nirl_learner("iq")  # the service's buffers: a demonstration buffer and the experience
    settings = ZenohSettings(mode="router", listen=[f"tcp/127.0.0.1:{free_port()}"], connect=[], run="dev")
    with open_session(settings) as session:
        config = NIRLConfig(**SMALL, warmstart_updates=2, q_updates=2, reward_updates=1)
        trainer = NIRLTrainer(
            config, NavConfig(), source.experience, source.demos, session, "dev", "test", 1, device
        )
        try:
            assert trainer.train(6) == 6 and trainer.version == 6
            assert all(p.device.type == device for p in trainer.learner.reward.parameters())
            assert all(p.device.type == device for p in trainer.learner.q.loss.parameters())
            assert source.demos.storage._storage.device.type == "cpu"
            trainer.save(tmp_path / "nirl")
            on_cpu = NIRLTrainer(
                config, NavConfig(), source.experience, source.demos, session, "dev", "test2", 1
            )
            on_cpu.load(tmp_path / "nirl")
            for name, value in trainer.learner.get_weights().items():
                np.testing.assert_array_equal(on_cpu.learner.get_weights()[name], value)
            on_cpu.close()
        finally:
            trainer.close()

"""--device cpu|cuda|auto: resolution, errors, and the learners on each device (CUDA runs only with a GPU)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from agents.device import resolve_device
from agents.nnql.learner import NNQLLearner
from services.cli import main
from tests.test_nnql_replay import N_ACTIONS, OBS_DIM, random_batch, small_config

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

"""The shared policy format: save/load, NNQL policies load too, clear errors for bad directories."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from agents.evaluation.policies import PolicyFormatError, load_policy, save_policy
from agents.nnql.policy import NNQLPolicy

ARCH = {"obs_dim": 11, "n_actions": 5, "hidden_sizes": [16, 8], "activation": "tanh"}


def _weights(rng: np.random.Generator) -> dict[str, np.ndarray]:
    sizes = [11, 16, 8, 5]
    out = {}
    for k, (i, o) in enumerate(itertools.pairwise(sizes)):
        out[f"{2 * k}.weight"] = rng.normal(size=(o, i)).astype(np.float32)
        out[f"{2 * k}.bias"] = rng.normal(size=o).astype(np.float32)
    return out


def test_round_trip_and_greedy_actions(tmp_path):
    rng = np.random.default_rng(0)
    weights = _weights(rng)
    save_policy(tmp_path / "p", weights, ARCH, model="imitation", kind="policy_logits", version=3, note="x")
    policy = load_policy(tmp_path / "p")
    assert (policy.model, policy.kind, policy.version, policy.obs_dim) == (
        "imitation",
        "policy_logits",
        3,
        11,
    )
    assert policy.config["note"] == "x"
    obs = rng.uniform(-1, 1, (50, 11)).astype(np.float32)
    h = np.tanh(obs @ weights["0.weight"].T + weights["0.bias"])
    h = np.tanh(h @ weights["2.weight"].T + weights["2.bias"])
    logits = h @ weights["4.weight"].T + weights["4.bias"]
    np.testing.assert_array_equal(policy(obs), logits.argmax(axis=1))
    assert policy(obs).dtype == np.int64
    with pytest.raises(ValueError, match="expected observations"):
        policy(obs[:, :5])


def test_nnql_policies_load_and_agree(tmp_path):
    rng = np.random.default_rng(1)
    nnql = NNQLPolicy(_weights(rng), ARCH, version=7)
    nnql.save(tmp_path / "q")
    policy = load_policy(tmp_path / "q")
    assert policy.kind == "q_network" and policy.version == 7
    obs = rng.uniform(-1, 1, (40, 11)).astype(np.float32)
    np.testing.assert_array_equal(policy(obs), nnql(obs))


def test_bad_directories_give_clear_errors(tmp_path):
    with pytest.raises(PolicyFormatError, match="not a policy directory"):
        load_policy(tmp_path)
    good = save_policy(tmp_path / "p", _weights(np.random.default_rng(2)), ARCH, "imitation", "policy_logits")
    config = json.loads((good / "config.json").read_text())
    (good / "config.json").write_text(json.dumps({**config, "kind": "transformer"}))
    with pytest.raises(PolicyFormatError, match="unknown policy kind"):
        load_policy(good)
    (good / "config.json").write_text(
        json.dumps({**config, "architecture": {**ARCH, "hidden_sizes": [16, 9]}})
    )
    with pytest.raises(PolicyFormatError, match="do not fit"):
        load_policy(good)
    (good / "config.json").write_text("{not json")
    with pytest.raises(PolicyFormatError, match="not valid JSON"):
        load_policy(good)
    (good / "config.json").write_text(json.dumps(config))
    (good / "model.safetensors").write_bytes(b"\x00" * 12)
    with pytest.raises(PolicyFormatError, match="unreadable"):
        load_policy(good)
    with pytest.raises(ValueError, match="kind"):
        save_policy(tmp_path / "x", {}, ARCH, "m", "value_function")

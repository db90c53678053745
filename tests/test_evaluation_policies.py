"""The shared policy format: save/load, NNQL policies load too, clear errors for bad directories."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from agents.evaluation.policies import PolicyFormatError, load_policy, save_policy
from agents.evaluation.runner import evaluate, make_eval_set
from agents.nnql.config import NNQLConfig
from agents.nnql.policy import NNQLPolicy
from worlds.config import (
    LEARNING_NAV,
    LEGACY_OBSERVATION,
    NavConfig,
    ObservationConfig,
    SensorConfig,
    observation_settings,
    with_observation,
)
from worlds.perception import observation_dim

PRETRAINED = Path(__file__).resolve().parents[1] / "pretrained" / "nnql"

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


OBSERVATIONS = {
    "legacy": NavConfig(),
    "sectors": NavConfig(sensors=SensorConfig(n_beams=24, n_rays=96)),
    "history": NavConfig(
        sensors=SensorConfig(n_beams=12, n_rays=24),
        observation=ObservationConfig(previous_action=True, frame_stack=3),
    ),
    "own-map-subgoal": NavConfig(observation=ObservationConfig(subgoal="own_map")),
    "known-map-subgoal": NavConfig(observation=ObservationConfig(subgoal="known_map")),
    "patch": NavConfig(observation=ObservationConfig(patch_size=5, frame_stack=2)),
}


def _random_policy(nav: NavConfig, seed: int = 0) -> NNQLPolicy:
    arch = {"obs_dim": observation_dim(nav), "n_actions": 5, "hidden_sizes": [32], "activation": "relu"}
    rng = np.random.default_rng(seed)
    weights = {
        "0.weight": rng.normal(size=(32, arch["obs_dim"])).astype(np.float32),
        "0.bias": rng.normal(size=32).astype(np.float32),
        "2.weight": rng.normal(size=(5, 32)).astype(np.float32),
        "2.bias": rng.normal(size=5).astype(np.float32),
    }
    return NNQLPolicy(weights, arch, observation=observation_settings(nav))


@pytest.mark.parametrize("name", list(OBSERVATIONS))
def test_saved_policy_with_each_observation_evaluates_identically_after_reload(tmp_path, name):
    nav = OBSERVATIONS[name]
    policy = _random_policy(nav)
    policy.save(tmp_path / name)
    assert json.loads((tmp_path / name / "config.json").read_text())["observation"] == observation_settings(
        nav
    )
    episodes = make_eval_set("unseen", 6, seed=5)
    before = evaluate(policy.greedy(), episodes, config=nav).episodes["unseen"]
    for reloaded in (load_policy(tmp_path / name), NNQLPolicy.load(tmp_path / name)):
        after = evaluate(reloaded, episodes).episodes["unseen"]  # the recorded settings make the env
        assert [(e.outcome, e.path_length, e.steps) for e in after] == [
            (e.outcome, e.path_length, e.steps) for e in before
        ]


def test_mismatched_observation_settings_fail_naming_the_field(tmp_path):
    _random_policy(OBSERVATIONS["history"]).save(tmp_path / "p")
    policy = load_policy(tmp_path / "p")
    episodes = make_eval_set("unseen", 2, seed=5)
    other = with_observation(OBSERVATIONS["history"], {"observation.frame_stack": 2})
    with pytest.raises(ValueError, match=r"observation\.frame_stack=3 \(the env has 2\)"):
        evaluate(policy, episodes, config=other)
    with pytest.raises(ValueError, match=r"sensors\.n_rays=24"):
        evaluate(policy, episodes, config=NavConfig(sensors=SensorConfig(n_beams=12)))
    config = json.loads((tmp_path / "p" / "config.json").read_text())
    config["observation"]["observation.frame_stack"] = 1  # no longer fits the network's inputs
    (tmp_path / "p" / "config.json").write_text(json.dumps(config))
    with pytest.raises(PolicyFormatError, match="give 20 inputs, the network takes obs_dim=60"):
        load_policy(tmp_path / "p")


def test_shipped_pretrained_policy_observes_what_policies_learn_with():
    policy = load_policy(PRETRAINED)
    assert policy.observation == observation_settings(LEARNING_NAV)
    assert observation_dim(policy.nav_config()) == policy.obs_dim == observation_dim(LEARNING_NAV)


def test_policy_saved_without_an_observation_record_evaluates_in_the_legacy_observation(tmp_path):
    """Every policy saved before the observation settings existed (the first pretrained/nnql)."""
    save_policy(tmp_path / "old", _weights(np.random.default_rng(2)), ARCH, model="nnql", kind="q_network")
    assert "observation" not in json.loads((tmp_path / "old" / "config.json").read_text())
    policy = load_policy(tmp_path / "old")
    assert policy.observation == LEGACY_OBSERVATION
    episodes = make_eval_set("unseen", 4, seed=5)
    legacy = evaluate(policy, episodes).episodes["unseen"]
    plain = evaluate(policy, episodes, config=NavConfig()).episodes["unseen"]
    assert [(e.outcome, e.steps) for e in legacy] == [(e.outcome, e.steps) for e in plain]
    with pytest.raises(ValueError, match=r"sensors\.n_beams=8 \(the env has 24\)"):
        evaluate(policy, episodes, config=LEARNING_NAV)


PRETRAINED_Q = [
    [0.963699, 1.048887, 1.090574, 0.221486, 1.056207],
    [0.969289, 0.957709, 0.956439, 0.972552, 1.020343],
    [-0.243149, -0.498229, -0.259321, -1.231467, 0.888505],
]
"""pretrained/nnql's Q-values on three seeded observations, read when issue 39 shipped it (the policy before
it, read on a731e15 before issue 42's refactor, is pinned in git history)"""


def test_the_shipped_policy_loads_and_computes_what_it_did_before_the_refactor():
    obs = np.random.default_rng(42).uniform(0, 1, (3, 30)).astype(np.float32)
    assert load_policy(PRETRAINED)(obs).tolist() == [2, 4, 4]
    flat = [q for row in NNQLPolicy.load(PRETRAINED).q_values(obs) for q in row]
    assert flat == pytest.approx([q for row in PRETRAINED_Q for q in row], abs=2e-5)
    saved = json.loads((PRETRAINED / "config.json").read_text())["nnql_config"]
    assert saved["recurrent"] is False  # saved with the retired variant's fields, which are dropped
    # saved with the variants' fields flat (q_network, action_local, cnn_*): read as the variant they
    # built, the action-local branch of window 3 = today's default recipe on its observation
    observation = json.loads((PRETRAINED / "config.json").read_text())["observation"]
    assert saved["q_network"] == "auto" and saved["action_local"] == 3 and "network" not in saved
    config = NNQLConfig.from_dict(saved, observation)
    assert config == NNQLConfig(seed=saved["seed"], network="local")
    assert config == NNQLConfig(seed=saved["seed"]).resolved(observation)
    assert NNQLConfig.from_dict(config.to_dict()) == config  # and today's files read back as written


def test_a_policy_or_config_of_the_retired_recurrent_variant_is_refused_in_one_sentence(tmp_path):
    """NNQL's recurrent variant is retired: what it saved is refused naming the commit that still runs it."""
    weights = {"0.weight": np.zeros((5, 30), np.float32), "0.bias": np.zeros(5, np.float32)}
    architecture = {"obs_dim": 30, "n_actions": 5, "hidden_sizes": [], "activation": "relu", "lstm_size": 8}
    save_policy(tmp_path / "lstm", weights, architecture, model="nnql", kind="q_network")
    with pytest.raises(PolicyFormatError, match=r"recurrent .* retired.*a731e15"):
        load_policy(tmp_path / "lstm")
    with pytest.raises(ValueError, match="retired"):
        NNQLConfig.from_dict({**NNQLConfig().to_dict(), "recurrent": True, "lstm_size": 64})
    older = {**NNQLConfig().to_dict(), "recurrent": False, "lstm_size": 64}  # a feed-forward run's config
    assert NNQLConfig.from_dict(older) == NNQLConfig()


def _with_config(tmp_path: Path, **changes) -> Path:
    """A copy of the shipped policy with ``changes`` to its config.json."""
    out = tmp_path / "policy"
    out.mkdir(parents=True)
    (out / "model.safetensors").write_bytes((PRETRAINED / "model.safetensors").read_bytes())
    config = json.loads((PRETRAINED / "config.json").read_text())
    config.update(changes)
    (out / "config.json").write_text(json.dumps(config))
    return out


def test_the_goal_distance_cap_is_what_the_network_reads(tmp_path):
    """goal_distance_cap: a goal further than the cap reads as the cap; a nearer one as it is."""
    capped = load_policy(_with_config(tmp_path, goal_distance_cap=20.0))
    plain = load_policy(_with_config(tmp_path / "b", goal_distance_cap=None))
    assert capped.goal_distance_cap == 20.0 and plain.goal_distance_cap is None
    rng = np.random.default_rng(0)
    obs = rng.uniform(0.1, 1.0, size=(3, capped.obs_dim)).astype(np.float32)
    squash = LEARNING_NAV.sensors.max_range
    far, at_cap, near = obs.copy(), obs.copy(), obs.copy()
    far[:, 24], at_cap[:, 24], near[:, 24] = 150 / (150 + squash), 20 / (20 + squash), 8 / (8 + squash)
    np.testing.assert_allclose(capped.outputs(far), plain.outputs(at_cap), rtol=1e-6)
    assert not np.allclose(plain.outputs(far), plain.outputs(at_cap))  # the cap changes what it reads
    np.testing.assert_array_equal(capped.outputs(near), plain.outputs(near))
    for bad in (0, -5, "far"):
        with pytest.raises(PolicyFormatError, match="goal_distance_cap"):
            load_policy(_with_config(tmp_path / f"bad{bad}", goal_distance_cap=bad))

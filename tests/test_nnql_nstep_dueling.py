"""n-step returns (agents/nnql/nstep.py, the learner's targets) and the dueling head (folded for actors)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from agents.evaluation.runner import evaluate, make_eval_set
from agents.nnql.config import NNQLConfig
from agents.nnql.learner import NNQLLearner
from agents.nnql.networks import DuelingQNetwork, QNetwork, export_weights, import_weights
from agents.nnql.nstep import NStepAccumulator
from agents.nnql.policy import NNQLPolicy
from worlds.config import LEARNING_NAV, observation_settings
from worlds.perception import observation_dim

GAMMA = 0.5


def step(t: int, reward: float, terminated: bool = False, truncated: bool = False, env: int = 0) -> dict:
    """One transition of robot ``env`` from state t to state t + 1 (obs = [t, env])."""
    return {
        "obs": np.array([[t, env]], np.float32),
        "action": np.array([t % 3]),
        "reward": np.array([reward], np.float32),
        "next_obs": np.array([[t + 1, env]], np.float32),
        "terminated": np.array([terminated]),
        "truncated": np.array([truncated]),
        "env_ids": np.array([env], np.int32),
    }


def feed(acc: NStepAccumulator, steps: list[dict], actor: str = "a") -> dict[str, np.ndarray]:
    outs = [acc(s, actor) for s in steps]
    return {k: np.concatenate([o[k] for o in outs]) for k in outs[0]}


def test_n_step_returns_stop_at_termination_and_bootstrap_at_truncation():
    acc = NStepAccumulator(3, GAMMA)
    # episode 1: states 0..4, terminated on the step 3 -> 4; episode 2: states 10..12, truncated on 11 -> 12
    out = feed(acc, [step(0, 1), step(1, 2), step(2, 4), step(3, 8, terminated=True)])
    out2 = feed(acc, [step(10, 1), step(11, 2, truncated=True)])
    assert acc.pending() == 0
    got = {int(o[0]): i for i, o in enumerate(out["obs"])}
    assert sorted(got) == [0, 1, 2, 3]
    expect = {  # obs -> (return, next state, terminated, discount)
        0: (1 + GAMMA * 2 + GAMMA**2 * 4, 3, False, GAMMA**3),
        1: (2 + GAMMA * 4 + GAMMA**2 * 8, 4, True, GAMMA**3),
        2: (4 + GAMMA * 8, 4, True, GAMMA**2),
        3: (8, 4, True, GAMMA),
    }
    for t, (ret, nxt, term, disc) in expect.items():
        i = got[t]
        assert out["reward"][i] == pytest.approx(ret)
        assert out["next_obs"][i][0] == nxt and bool(out["terminated"][i]) == term
        assert out["discount"][i] == pytest.approx(disc) and out["action"][i] == t % 3
    got2 = {int(o[0]): i for i, o in enumerate(out2["obs"])}
    for t, ret, disc in ((10, 1 + GAMMA * 2, GAMMA**2), (11, 2, GAMMA)):
        i = got2[t]
        assert out2["reward"][i] == pytest.approx(ret) and out2["discount"][i] == pytest.approx(disc)
        assert out2["next_obs"][i][0] == 12 and not out2["terminated"][i] and out2["truncated"][i]


def test_n_step_streams_are_per_actor_and_robot_and_cut_where_they_break():
    acc = NStepAccumulator(2, GAMMA)
    out = feed(acc, [step(0, 1, env=0), step(0, 5, env=1), step(1, 2, env=0)], actor="a")
    assert out["obs"].tolist() == [[0, 0]] and out["reward"][0] == pytest.approx(1 + GAMMA * 2)
    assert acc(step(0, 7, env=0), "b")["obs"].shape == (0, 2)  # another actor's robot 0: its own stream
    # robot 1 of actor a jumps from state 1 to 7 (a restarted actor): the waiting step bootstraps from 1
    cut = acc(step(7, 3, env=1), "a")
    assert cut["obs"].tolist() == [[0, 1]] and cut["next_obs"].tolist() == [[1, 1]]
    assert cut["reward"][0] == pytest.approx(5) and cut["discount"][0] == pytest.approx(GAMMA)
    assert not cut["terminated"][0]


def test_learner_n_step_targets_use_the_discount_per_transition():
    obs_dim = 2
    learner = NNQLLearner(NNQLConfig(n_step=3, gamma=GAMMA, batch_size=4, learning_starts=4), obs_dim, 3)
    with pytest.raises(KeyError, match="env_ids"):
        learner.add({k: v for k, v in step(0, 1).items() if k != "env_ids"})
    for s in [step(0, 1), step(1, 2), step(2, 4), step(3, 8, terminated=True)]:
        learner.add(s)
    assert len(learner.replay) == 4
    batch = learner._sample(4)[1]
    assert batch.discount is not None
    with torch.no_grad():
        next_q = learner.lean.next_value(batch)
        _, priority = learner.lean.loss(batch)
        predicted = learner.network(batch.obs).gather(-1, batch.action.long().unsqueeze(-1)).squeeze(-1)
    target = batch.reward + batch.discount * (~batch.terminated.bool()).float() * next_q
    torch.testing.assert_close(priority, (predicted - target) ** 2)
    learner.update(2)
    assert learner.version == 2


@pytest.mark.parametrize("field,value", [("n_step", 0), ("n_step", -2), ("n_step", 1.5)])
def test_bad_n_step_raises_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"NNQLConfig.{field}"):
        NNQLConfig(**{field: value})
    with pytest.raises(ValueError, match="n_step"):
        NNQLConfig(n_step=3, sarsa=True, double_q=False)


@pytest.mark.parametrize("activation", ["relu", "tanh", "elu"])
def test_dueling_numpy_forward_equals_torch_and_unfolds_exactly(activation):
    torch.manual_seed(0)
    net = DuelingQNetwork(6, 5, [16, 8], activation)
    with torch.no_grad():
        for p in net.parameters():
            p.normal_(0, 0.5)
    x = np.random.default_rng(0).normal(size=(32, 6)).astype(np.float32)
    want = net(torch.as_tensor(x)).detach().numpy()
    policy = NNQLPolicy(export_weights(net), net.architecture)
    np.testing.assert_allclose(policy.q_values(x), want, rtol=1e-5, atol=1e-5)
    again = QNetwork.from_architecture(net.architecture)
    assert isinstance(again, DuelingQNetwork)
    import_weights(again, export_weights(net))
    np.testing.assert_allclose(again(torch.as_tensor(x)).detach().numpy(), want, rtol=1e-5, atol=1e-5)


def test_dueling_policy_saved_and_reloaded_evaluates_identically(tmp_path):
    obs_dim = observation_dim(LEARNING_NAV)
    config = NNQLConfig(dueling=True, n_step=3, hidden_sizes=(32, 32))
    learner = NNQLLearner(config, obs_dim, 5, observation=observation_settings(LEARNING_NAV))
    with torch.no_grad():
        for p in learner.network.parameters():
            p.normal_(0, 0.3)
    learner.save_policy(tmp_path / "p")
    loaded = NNQLPolicy.load(tmp_path / "p")
    assert loaded.architecture["dueling"] is True
    eval_set = make_eval_set("unseen", 6, seed=3)
    a = evaluate(learner.policy(), eval_set, config=LEARNING_NAV)
    b = evaluate(loaded, eval_set, config=LEARNING_NAV)
    assert [e.outcome for e in a.episodes["unseen"]] == [e.outcome for e in b.episodes["unseen"]]
    assert [e.steps for e in a.episodes["unseen"]] == [e.steps for e in b.episodes["unseen"]]


def test_plain_network_layout_is_unchanged_so_old_policies_load():
    net = QNetwork(4, 3, [8], "relu")
    assert "dueling" not in net.architecture
    assert export_weights(net).keys() == net.state_dict().keys()


def test_n_step_dueling_learner_checkpoint_keeps_discounts_and_weights(tmp_path):
    config = NNQLConfig(
        n_step=3, gamma=GAMMA, dueling=True, hidden_sizes=(8,), batch_size=2, learning_starts=2
    )
    learner = NNQLLearner(config, 2, 3)
    for s in [step(0, 1), step(1, 2), step(2, 4), step(3, 8, truncated=True)]:
        learner.add(s)
    learner.update(1)
    learner.save_checkpoint(tmp_path / "ckpt")
    again = NNQLLearner.from_checkpoint(tmp_path / "ckpt")
    assert isinstance(again.network, DuelingQNetwork) and len(again.replay) == 4
    stored = again._columns()
    np.testing.assert_allclose(
        np.sort(stored.discount[:4].numpy()), np.sort([GAMMA**3, GAMMA**3, GAMMA**2, GAMMA])
    )
    for name, value in learner.get_weights().items():
        np.testing.assert_array_equal(again.get_weights()[name], value)

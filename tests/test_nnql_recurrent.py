"""Recurrent NNQL (issue 14, variant G): memory reset per episode, within-episode sequences, policy files."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from agents.evaluation.policies import GreedyRecurrentPolicy, load_policy
from agents.evaluation.runner import evaluate, make_eval_set
from agents.nnql.config import NNQLConfig
from agents.nnql.recurrent_learner import RecurrentNNQLLearner
from agents.nnql.recurrent_policy import RecurrentNNQLPolicy
from agents.nnql.recurrent_rollout import RecurrentRollout
from agents.nnql.sequence_replay import SequenceReplay, StreamEpisodes, sequence_tensordict
from worlds.config import NavConfig, SensorConfig, observation_settings
from worlds.perception import observation_dim

OBS_DIM, N_ACTIONS, LSTM = 6, 5, 8


def small_config(**overrides) -> NNQLConfig:
    options = dict(recurrent=True, hidden_sizes=(16, 16), lstm_size=LSTM, seq_len=4, burn_in=2, sequences=8,
                   batch_size=8, replay_capacity=4096, learning_starts=64, seed=3)  # fmt: skip
    return NNQLConfig(**{**options, **overrides})


class ScriptedVectorEnv:
    """A vector env in SAME_STEP autoreset mode whose robots' episodes end after scripted lengths."""

    def __init__(self, lengths: list[list[int]], seed: int = 0):
        self.lengths = lengths
        self.num_envs = len(lengths)
        self.rng = np.random.default_rng(seed)
        self.t = np.zeros(self.num_envs, np.int64)
        self.episode = np.zeros(self.num_envs, np.int64)

    def _obs(self) -> np.ndarray:
        return self.rng.normal(size=(self.num_envs, OBS_DIM)).astype(np.float32)

    def reset(self, seed=None, options=None):
        self.t[:] = 0
        return self._obs(), {}

    def step(self, actions):
        self.t += 1
        limit = np.array([ls[min(e, len(ls) - 1)] for ls, e in zip(self.lengths, self.episode, strict=True)])
        done = self.t >= limit
        obs = self._obs()
        info = {}
        if done.any():
            info = {"final_obs": self._obs(), "_final_obs": done, "final_info": {}}
            self.t[done] = 0
            self.episode[done] += 1
        reward = np.zeros(self.num_envs, np.float32)
        return obs, reward, done, np.zeros(self.num_envs, bool), info


def random_policy(seed: int = 0) -> RecurrentNNQLPolicy:
    learner = RecurrentNNQLLearner(small_config(seed=seed), OBS_DIM, N_ACTIONS)
    return learner.policy(mode="greedy")


def test_rollout_resets_the_memory_of_a_robot_whose_episode_ended():
    env = ScriptedVectorEnv([[3, 5], [7, 2], [4, 4]])
    policy = random_policy()
    rollout = RecurrentRollout(env, policy)
    rollout.reset(seed=0)
    batches = [rollout.step()[0] for _ in range(9)]
    for robot, ends in enumerate([(3, 8), (7, 9), (4, 8)]):
        starts = {0, *[e for e in ends if e < 9]}
        for t, batch in enumerate(batches):
            state = np.abs(batch["state_h"][robot]).sum() + np.abs(batch["state_c"][robot]).sum()
            assert (batch["step"][robot] == 0) == (t in starts)
            assert (state == 0.0) == (t in starts), (robot, t)  # zero state exactly at episode starts
    episodes = np.array([b["episode"] for b in batches])  # (T, robots): each robot's episode number
    assert list(episodes[:, 0]) == [0, 0, 0, 1, 1, 1, 1, 1, 2]
    assert list(episodes[:, 1]) == [0] * 7 + [1, 1]
    assert all(list(b["env_ids"]) == [0, 1, 2] for b in batches)
    # the first action of a new episode is what a fresh memory picks for that observation
    fresh = policy.greedy()
    fresh.reset_state(np.ones(1, bool))
    first = batches[3]["obs"][0:1]
    assert fresh.q_values(first).argmax() == batches[3]["action"][0]


def interleaved_replay(lengths: dict[int, list[int]], slice_len: int) -> tuple[SequenceReplay, int]:
    """Robots' transitions interleaved step by step, episodes of the given lengths; obs = robot, ep, step."""
    streams = StreamEpisodes()
    rows = {"robot": [], "episode": [], "step": []}
    counters = {r: [0, 0] for r in lengths}  # episode index, step
    total = max(sum(v) for v in lengths.values())
    for _ in range(total):
        for robot, eps in lengths.items():
            e, s = counters[robot]
            if e >= len(eps):
                continue
            rows["robot"].append(robot)
            rows["episode"].append(e)
            rows["step"].append(s)
            counters[robot] = [e + 1, 0] if s + 1 == eps[e] else [e, s + 1]
    n = len(rows["robot"])
    robot, episode, step = (np.array(rows[k]) for k in ("robot", "episode", "step"))
    ends = np.array([step[i] + 1 == lengths[robot[i]][episode[i]] for i in range(n)])
    obs = np.stack([robot, episode, step, *np.zeros((OBS_DIM - 3, n))], axis=1).astype(np.float32)
    flat = {
        "obs": obs, "action": np.zeros(n, np.int64), "reward": np.zeros(n, np.float32), "next_obs": obs + 0.5,
        "terminated": ends, "truncated": np.zeros(n, bool),
        "episode": streams.ids([("actor", r) for r in robot], episode), "step": step,
        "state_h": np.zeros((n, LSTM), np.float32), "state_c": np.zeros((n, LSTM), np.float32),
    }  # fmt: skip
    replay = SequenceReplay(10_000, slice_len, torch.Generator().manual_seed(0))
    replay.extend(sequence_tensordict(flat, OBS_DIM, LSTM))
    return replay, n


def test_sampled_sequences_never_cross_an_episode_boundary_nor_mix_robots():
    lengths = {0: [3, 11, 6, 1, 9], 1: [12, 2, 8], 2: [5, 5, 5, 4], 3: [1, 1, 20]}
    replay, n = interleaved_replay(lengths, slice_len=6)
    assert len(replay) == n
    seen_short = False
    for _ in range(30):
        seq = replay.sample_sequences(16)
        for k in range(16):
            real = seq.mask[k].numpy()
            assert real[0] and (np.diff(real.astype(int)) <= 0).all()  # padding only after the real steps
            obs = seq.obs[k][torch.as_tensor(real)].numpy()
            robot, episode, step = obs[:, 0], obs[:, 1], obs[:, 2]
            assert (robot == robot[0]).all() and (episode == episode[0]).all()
            assert (np.diff(step) == 1).all()  # consecutive steps of one episode
            assert (seq.step[k][torch.as_tensor(real)].numpy() == step).all()
            length = lengths[int(robot[0])][int(episode[0])]
            assert step[-1] < length
            if len(step) < 6:  # a short slice: its episode is shorter than a slice, taken whole
                seen_short = True
                assert len(step) == length and step[0] == 0
    assert seen_short


def test_stream_episodes_give_new_ids_per_stream_and_episode():
    streams = StreamEpisodes()
    ids = streams.ids([("a", 0), ("a", 1), ("b", 0), ("a", 0), ("a", 0)], np.array([0, 0, 0, 0, 1]))
    assert list(ids) == [0, 1, 2, 0, 3]


def test_numpy_policy_matches_the_torch_unroll_and_updates_advance():
    learner = RecurrentNNQLLearner(small_config(), OBS_DIM, N_ACTIONS)
    policy = learner.policy()
    policy.reset_state(np.ones(3, bool))
    obs = np.random.default_rng(1).normal(size=(3, 7, OBS_DIM)).astype(np.float32)
    stepped = np.stack([policy.q_values(obs[:, t]) for t in range(7)], axis=1)
    zeros = torch.zeros(3, LSTM)
    with torch.no_grad():
        unrolled, _ = learner.network.unroll(torch.as_tensor(obs), (zeros, zeros))
    np.testing.assert_allclose(stepped, unrolled.numpy(), atol=1e-5)

    env = ScriptedVectorEnv([[5, 9, 3, 12], [7, 2, 30], [4, 4, 4, 4, 20]], seed=2)
    rollout = RecurrentRollout(env, learner.policy(mode="boltzmann", temperature=1.0, seed=0))
    rollout.reset()
    while not learner.ready():
        learner.add(rollout.step()[0])
    before = learner.get_weights()
    metrics = learner.update(3)
    assert learner.version == 3 and np.isfinite(metrics["losses/td_loss"])
    assert 0 < metrics["losses/trained_steps"] <= 8 * 6
    assert any(not np.array_equal(before[k], v) for k, v in learner.get_weights().items())


def test_saved_recurrent_policy_evaluates_identically_after_reload(tmp_path):
    nav = NavConfig(sensors=SensorConfig(n_beams=24, n_rays=96))
    learner = RecurrentNNQLLearner(
        small_config(), observation_dim(nav), nav.robot.n_actions, observation=observation_settings(nav)
    )
    learner.save_policy(tmp_path / "policy")
    loaded = load_policy(tmp_path / "policy")
    assert isinstance(loaded, GreedyRecurrentPolicy)
    assert RecurrentNNQLPolicy.load(tmp_path / "policy").architecture["lstm_size"] == LSTM
    eval_set = make_eval_set("unseen", 12, seed=5)
    direct = evaluate(learner.policy().greedy(), eval_set, config=nav)
    reloaded = evaluate(loaded, eval_set, config=nav, max_batch=5)  # other waves: memory reset per episode
    a, b = direct.episodes["unseen"], reloaded.episodes["unseen"]
    assert [(e.outcome, e.steps) for e in a] == [(e.outcome, e.steps) for e in b]
    assert all(np.array_equal(x.trajectory, y.trajectory) for x, y in zip(a, b, strict=True))
    assert max(e.steps for e in a) > 1  # the memory was carried over several steps


@pytest.mark.parametrize(
    "field, value", [("lstm_size", 0), ("seq_len", 0), ("burn_in", -1), ("sequences", 0)]
)
def test_bad_recurrent_options_raise_naming_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        NNQLConfig(recurrent=True, **{field: value})


def test_checkpoint_restores_weights_replay_and_keeps_trajectory_ids_unique(tmp_path):
    learner = RecurrentNNQLLearner(small_config(), OBS_DIM, N_ACTIONS)
    rollout = RecurrentRollout(ScriptedVectorEnv([[5, 9, 3], [7, 2, 30]]), learner.policy(seed=0))
    rollout.reset()
    while not learner.ready():
        learner.add(rollout.step()[0])
    learner.update(2)
    learner.save_checkpoint(tmp_path / "ckpt")
    resumed = RecurrentNNQLLearner(small_config(), OBS_DIM, N_ACTIONS)
    resumed.load_checkpoint(tmp_path / "ckpt")
    assert resumed.version == 2 and len(resumed.replay) == len(learner.replay)
    assert all(np.array_equal(v, resumed.get_weights()[k]) for k, v in learner.get_weights().items())
    stored = resumed.replay.storage.get(torch.arange(len(resumed.replay))).get("episode")
    # a restarted actor numbers its episodes from 0 again: they must not reuse a stored id
    fresh = RecurrentRollout(ScriptedVectorEnv([[4, 4]]), resumed.policy())
    fresh.reset()
    resumed.add(fresh.step()[0])
    newest = resumed.replay.storage.get(torch.arange(len(resumed.replay))).get("episode")[-1]
    assert int(newest) > int(stored.max())
    resumed.update(1)  # the fragmented sampler finds every (episode, step) pair unique


@pytest.mark.parametrize("update, period", [("soft", 1), ("hard", 2)])
def test_target_network_follows_the_online_one(update, period):
    config = small_config(target_update=update, target_period=period)
    learner = RecurrentNNQLLearner(config, OBS_DIM, N_ACTIONS)
    rollout = RecurrentRollout(ScriptedVectorEnv([[5, 9, 3], [7, 2, 30]]), learner.policy(seed=0))
    rollout.reset()
    while not learner.ready():
        learner.add(rollout.step()[0])
    before = [p.detach().clone() for p in learner.target.parameters()]
    learner.update(1)
    online = list(learner.network.parameters())
    for old, new, now in zip(before, learner.target.parameters(), online, strict=True):
        expected = old if update == "hard" else old + learner.config.target_tau * (now.detach() - old)
        torch.testing.assert_close(new, expected)
    learner.update(1)
    if update == "hard":  # copied at every period-th update
        for new, now in zip(learner.target.parameters(), learner.network.parameters(), strict=True):
            torch.testing.assert_close(new, now.detach())

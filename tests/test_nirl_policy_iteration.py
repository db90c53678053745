"""NIRL's NNQL phase (agents/nirl/policy_iteration.py): the fixed learned reward is the one the
replay holds, the environment's reward never reaches it, and `train_nirl` hands over to NNQL's trainer."""

import json

import numpy as np
import pytest
import torch
from safetensors.numpy import load_file

from agents.nirl import train_local as nirl_train
from agents.nirl.config import NIRLConfig, NIRLRun
from agents.nirl.learner import NIRLLearner
from agents.nirl.losses import KEEP, RELABEL, Refinement
from agents.nirl.networks import goal_reached
from agents.nirl.policy_iteration import FixedReward, nnql_config, warm_weights
from agents.nirl.progress import ProgressPotential, shaped_progress_reward
from agents.nirl.train_local import train_nirl
from agents.nirl.weights import WeightHistory
from agents.nnql.config import NNQLConfig
from agents.nnql.learner import NNQLLearner
from agents.nnql.train_local import LocalTrainConfig, train_local
from agents.planning.demonstrate import generate_demos
from worlds.config import LEARNING_NAV
from worlds.perception import observation_dim
from worlds.vector_env import NavigationVectorEnv

GAMMA = 0.99
N_BEAMS = LEARNING_NAV.sensors.n_beams


def potential_reward(seed: int = 0) -> FixedReward:
    torch.manual_seed(seed)
    potential = ProgressPotential(observation_dim(LEARNING_NAV), (16,), "relu", GAMMA)
    return FixedReward(potential, GAMMA, N_BEAMS, LEARNING_NAV.goal_tolerance, LEARNING_NAV.sensors.max_range)


@pytest.fixture
def nan_env_reward(monkeypatch):
    """The environment pays NaN for every step: any learner that reads it learns NaN."""
    step = NavigationVectorEnv.step

    def poisoned(self, actions):
        obs, reward, terminated, truncated, info = step(self, actions)
        return obs, np.full_like(np.asarray(reward, dtype=np.float32), np.nan), terminated, truncated, info

    monkeypatch.setattr(NavigationVectorEnv, "step", poisoned)


def stored(learner) -> dict:
    steps = learner.replay.storage.get(torch.arange(len(learner.replay)))
    return {
        "obs": steps["observation"].numpy(),
        "next_obs": steps[("next", "observation")].numpy(),
        "terminated": steps[("next", "terminated")].reshape(-1).numpy(),
        "reward": steps[("next", "reward")].reshape(-1).numpy(),
    }


def test_fixed_reward_is_the_shaped_progress_reward_of_the_batch():
    reward = potential_reward()
    rng = np.random.default_rng(0)
    dim = observation_dim(LEARNING_NAV)
    obs, next_obs = rng.random((6, dim), dtype=np.float32), rng.random((6, dim), dtype=np.float32)
    terminated = np.array([False, False, True, True, False, False])
    batch = {"obs": obs, "next_obs": next_obs, "terminated": terminated}
    batch["next_obs"][3, N_BEAMS] = 0.0  # the goal reached on step 3, a collision on step 2
    got = reward(batch)
    obs, next_obs = torch.as_tensor(batch["obs"]), torch.as_tensor(batch["next_obs"])
    at_goal = goal_reached(next_obs, N_BEAMS, LEARNING_NAV.goal_tolerance, LEARNING_NAV.sensors.max_range)
    assert at_goal.tolist() == [False, False, False, True, False, False]
    expected = shaped_progress_reward(reward.potential, obs, next_obs, torch.as_tensor(batch["terminated"]),
                                      at_goal, GAMMA)  # fmt: skip
    assert got.dtype == np.float32 and np.allclose(got, (1 - GAMMA) * expected.numpy())
    assert got[2] < -0.5 < got[3]  # the collision's absorbing never-arriving value, the goal's zero potential


def test_the_env_reward_never_reaches_nnqls_replay_when_the_learned_reward_is_given(nan_env_reward):
    run = LocalTrainConfig(steps=400, envs=4, eval_every=0, final_eval_episodes=0, out="", progress=False,
                           moving_discs=0, maps="mixed:16")  # fmt: skip
    nnql = NNQLConfig(learning_starts=64, batch_size=32, utd_ratio=0.25, gamma=GAMMA)
    reward = potential_reward()
    result = train_local(run, nnql, reward=reward)
    data = stored(result.learner)
    assert len(data["reward"]) == 400 and np.isfinite(data["reward"]).all()
    assert np.allclose(data["reward"], reward(data), atol=1e-5)
    assert result.updates > 0
    assert all(np.isfinite(w).all() for w in result.learner.get_weights().values())
    # the counter-check: without the learned reward the same poisoned env fills the replay with NaN
    plain = train_local(run, nnql)
    assert np.isnan(stored(plain.learner)["reward"]).all()


def test_train_nirl_runs_iq_rounds_then_nnqls_trainer_on_the_fixed_reward(nan_env_reward, tmp_path):
    demos, _ = generate_demos("mixed:16", 3, seed=0, config=LEARNING_NAV)
    config = NIRLConfig(iterations=3, fix_reward_after=1, warmstart_updates=10, q_updates=8, reward_updates=4,
                        steps_per_iteration=64, policy_steps=320, seed=0)  # fmt: skip
    run = NIRLRun(envs=4, maps="mixed:16", out=str(tmp_path / "run"), eval_every=0, final_eval_episodes=0,
                  progress=False, policy_eval_every=0)  # fmt: skip
    result = train_nirl(demos, config, run)
    assert result.learner.iteration == 1 and result.iq_steps == 64  # only the IQ-Learn rounds
    assert result.env_steps == 64 + 320 and result.policy_result.env_steps == 320
    assert result.policy_result.policy is not None
    data = stored(result.policy_result.learner)
    assert np.isfinite(data["reward"]).all()
    assert np.allclose(data["reward"], FixedReward.of(result.learner)(data), atol=1e-5)
    assert (tmp_path / "run" / "policy_iteration" / "model.safetensors").exists()


def test_policy_steps_needs_the_progress_reward_fixed_after_iq_rounds():
    with pytest.raises(ValueError, match="policy_steps"):
        NIRLConfig(policy_steps=1000, fix_reward_after=0)
    with pytest.raises(ValueError, match="policy_steps"):
        NIRLConfig(policy_steps=1000, fixed_reward="network")


def test_warm_start_hands_nirls_q_to_nnqls_trainer_in_its_reward_units(nan_env_reward):
    """policy_warm_start: NIRL's own rounds go on `policy_warm_start` rounds on the fixed reward, then
    NNQL's (dueling) network starts from NIRL's Q times 1 - gamma - the same greedy policy - at the
    constant policy_temperature, and learns on from there."""
    demos, _ = generate_demos("mixed:16", 3, seed=0, config=LEARNING_NAV)
    config = NIRLConfig(
        iterations=9,
        fix_reward_after=1,
        policy_warm_start=2,
        warmstart_updates=10,
        q_updates=8,
        reward_updates=4,
        steps_per_iteration=64,
        policy_steps=2400,
        policy_utd=0.25,
        policy_temperature=0.02,
        seed=0,
        network="mlp",  # the warm start hands over the plain MLP's layout
        gamma=GAMMA,
    )
    with pytest.raises(ValueError, match="--network mlp"):
        NIRLConfig(policy_warm_start=2)
    assert config.own_rounds() == 3 and NIRLConfig(iterations=9).own_rounds() == 9
    run = NIRLRun(envs=4, maps="mixed:16", out="", eval_every=0, final_eval_episodes=0, progress=False,
                  policy_eval_every=0)  # fmt: skip
    result = train_nirl(demos, config, run)
    assert result.learner.iteration == 3 and result.learner.reward_fixed and result.iq_steps == 3 * 64
    nnql = nnql_config(config)
    assert nnql.dueling and nnql.temperature_start == nnql.temperature_end == 0.02
    # what the phase started from: NNQL's dueling network holding NIRL's Q in the fixed reward's units
    start = NNQLLearner(nnql, result.learner.obs_dim, result.learner.n_actions, observation=None)
    start.set_weights(warm_weights(result.learner, config))
    obs = np.asarray(stored(result.policy_result.learner)["obs"][:200], dtype=np.float32)
    nirl_q = result.learner.q.q_values(obs)
    assert np.allclose(start.q_values(obs), (1 - GAMMA) * nirl_q, rtol=1e-4, atol=1e-6)
    assert (start.q_values(obs).argmax(1) == nirl_q.argmax(1)).all()
    # ... and learned on from it: the phase's updates moved the weights
    phase = result.policy_result.learner
    assert phase.updates > 0 and not np.allclose(phase.q_values(obs), start.q_values(obs))


def test_train_local_starts_from_the_initial_weights_it_is_given():
    run = LocalTrainConfig(steps=32, envs=4, eval_every=0, final_eval_episodes=0, out="", progress=False,
                           moving_discs=0)  # fmt: skip
    # no update within 32 robot-steps; the MLP alone, the layout of the initial weights
    nnql = NNQLConfig(learning_starts=10_000, gamma=GAMMA, network="mlp")
    donor = NNQLLearner(NNQLConfig(seed=7), observation_dim(LEARNING_NAV), LEARNING_NAV.robot.n_actions)
    result = train_local(run, nnql, initial_weights=donor.get_weights())
    obs = np.random.default_rng(0).random((50, observation_dim(LEARNING_NAV)), dtype=np.float32)
    assert result.updates == 0
    assert np.allclose(result.learner.q_values(obs), donor.q_values(obs), atol=1e-6)
    assert np.allclose(result.policy.q_values(obs), donor.q_values(obs), atol=1e-5)


@pytest.mark.parametrize(("field", "value"), [("policy_warm_start", -1), ("policy_temperature", 0.0)])
def test_bad_warm_start_options_name_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        NIRLConfig(**{field: value})


def test_nirls_own_rounds_collect_experience_with_the_moving_disc_mix_asked_for(monkeypatch):
    made = []

    class Recording(NavigationVectorEnv):
        def __init__(self, *args, config=None, **kwargs):
            made.append(config)
            super().__init__(*args, config=config, **kwargs)

    monkeypatch.setattr(nirl_train, "NavigationVectorEnv", Recording)
    demos, _ = generate_demos("mixed:16", 2, seed=0, config=LEARNING_NAV)
    config = NIRLConfig(
        iterations=1, warmstart_updates=2, q_updates=2, reward_updates=1, steps_per_iteration=32
    )
    for discs in (0, 3):
        run = NIRLRun(envs=4, out="", eval_every=0, final_eval_episodes=0, progress=False, moving_discs=discs)
        train_nirl(demos, config, run)
        assert made[-1].obstacles.count == discs and made[-1].obstacles.mix == (discs > 0)


def test_relabelled_demonstrations_train_the_fixed_reward_phase_on_the_action_that_was_taken():
    """TD learns what happened: a demonstrated step's next state is the recorded action's, so MAP
    refinement's relabel (every step here) must not change the fixed-reward phase's update; the
    phase does not run the refinement (nor chart it) at all."""
    demos, _ = generate_demos("mixed:16", 2, seed=0, config=LEARNING_NAV)
    config = NIRLConfig(hidden_sizes=(16,), batch_size=16, demo_fraction=0.5)
    learners = []
    for relabel in (False, True):
        torch.manual_seed(0)
        learner = NIRLLearner(config, LEARNING_NAV)
        learner.add_demos(demos)
        learner.fix_reward()
        learners.append((learner, relabel))
    batch, is_expert = learners[0][0].fit.mixed_batch(offline=True)
    losses = []
    for learner, relabel in learners:
        fit = learner.fit

        def refine(obs, actions, noise, relabel=relabel):
            labels = (actions + 1) % 5 if relabel else actions
            decisions = torch.full_like(actions, RELABEL if relabel else KEEP)
            return Refinement(labels, torch.ones(len(actions)), decisions)

        fit.refine = refine
        fit.mixed_batch = lambda offline, batch=batch, is_expert=is_expert: (batch.clone(), is_expert)
        metrics = fit.q_step()
        assert not any(name.startswith("charts/refine_") for name in metrics)
        losses.append(metrics["losses/td_loss"])
    assert losses[0] == losses[1]
    for name, value in learners[0][0].get_weights().items():
        assert np.array_equal(learners[1][0].get_weights()[name], value), name


def four_tiny_rounds() -> tuple[list, NIRLConfig]:
    """Two expert demonstrations and a NIRL config of four tiny rounds (the reward fixed after one)."""
    demos, _ = generate_demos("mixed:16", 2, seed=0, config=LEARNING_NAV)
    config = NIRLConfig(
        hidden_sizes=(16,), iterations=4, warmstart_updates=2, q_updates=8, reward_updates=1,
        steps_per_iteration=32, fix_reward_after=1,
    )  # fmt: skip
    return demos, config


def test_keep_best_keeps_the_own_round_that_validated_best(tmp_path):
    demos, config = four_tiny_rounds()
    run = NIRLRun(envs=4, out=str(tmp_path / "kept"), eval_every=1, eval_episodes=6, final_eval_episodes=0,
                  progress=False, keep_best=True)  # fmt: skip
    result = train_nirl(demos, config, run)
    scores = [(p["eval_success"], p["eval_spl"], p["iteration"]) for p in result.curve]
    assert len(scores) == 4  # every round validated, the last one included
    best = int(max(scores)[2])
    assert result.selected_iteration == best
    kept = result.history.snapshots
    at = result.history.iterations.index(best)
    saved = load_file(str(tmp_path / "kept" / "model.safetensors"))
    for name, value in result.learner.get_weights().items():
        # a dueling head's exported weights are folded into one layer: a round trip moves the last bit
        assert np.allclose(value, kept[f"policy/{name}"][at], atol=1e-6)
        assert np.array_equal(saved[name], value)
    summary = json.loads((tmp_path / "kept" / "summary.json").read_text())
    assert summary["selected_iteration"] == best
    last = train_nirl(demos, config, NIRLRun(envs=4, out="", eval_every=1, eval_episodes=6, keep_best=False,
                                             final_eval_episodes=0, progress=False))  # fmt: skip
    assert last.selected_iteration is None
    for name, value in last.learner.get_weights().items():
        assert np.array_equal(value, last.history.snapshots[f"policy/{name}"][-1])
    # validating reads the greedy policy only: the same rounds as a run that never validates
    # (results/nirl/scripts/nirl_last_round.py tests a keep-best run's last round as that run's result)
    silent = train_nirl(demos, config, NIRLRun(envs=4, out="", eval_every=0, final_eval_episodes=0,
                                               progress=False))  # fmt: skip
    for name, stack in silent.history.snapshots.items():
        other = last.history.snapshots[name]
        assert all(np.array_equal(a, b) for a, b in zip(stack, other, strict=True)), name


def test_the_policy_averages_the_last_rounds_weights(tmp_path):
    demos, config = four_tiny_rounds()
    run = NIRLRun(envs=4, out=str(tmp_path / "avg"), eval_every=0, final_eval_episodes=0, progress=False,
                  average_last=0.5)  # fmt: skip
    result = train_nirl(demos, config, run)
    assert result.averaged_rounds == 2 and run.averaged_rounds(200) == 100
    rounds = result.history.snapshots
    saved = load_file(str(tmp_path / "avg" / "model.safetensors"))
    for name, value in result.learner.get_weights().items():
        mean = (rounds[f"policy/{name}"][-1] + rounds[f"policy/{name}"][-2]) / 2
        assert np.allclose(value, mean, atol=1e-5) and not np.allclose(value, rounds[f"policy/{name}"][-1])
        assert np.array_equal(saved[name], value)
    assert json.loads((tmp_path / "avg" / "summary.json").read_text())["averaged_rounds"] == 2
    with pytest.raises(ValueError, match="average_last"):
        NIRLRun(average_last=1.5)


def test_a_weight_history_averages_its_last_records():
    history = WeightHistory()
    for k in range(3):
        history.record(k, policy={"w": np.full(2, k, np.float32)}, reward={"b": np.zeros(1, np.float32)})
    assert np.array_equal(history.averaged("policy", 2)["w"], [1.5, 1.5])
    assert set(history.averaged("policy", 3)) == {"w"}
    with pytest.raises(ValueError, match="last=4 outside the 3"):
        history.averaged("policy", 4)

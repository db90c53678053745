"""NIRL learner: reward recovery on the grid world, MAP refinement on known noise, tiny maps solved
end to end across seeds, checkpoints (old and new formats), weight history."""

import math

import numpy as np
import pytest
import torch

from agents.nirl.config import NIRLConfig, NIRLRun
from agents.nirl.learner import NIRLLearner
from agents.nirl.losses import KEEP
from agents.nirl.persistence import load_nirl_state, nirl_state
from worlds.config import NavConfig

TINY_MAP = """\
##########
#S.......#
#........#
#...##...#
#...##...#
#........#
#.......G#
##########
"""

SMALL = {
    "hidden_sizes": (32, 32),
    "reward_hidden_sizes": (32,),
    "batch_size": 64,
    "demo_batch_size": 64,
    "replay_capacity": 20_000,
}


def goal_seeking_steps(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Random observations and the action whose turn faces the goal best (a synthetic expert)."""
    rng = np.random.default_rng(seed)
    obs = rng.uniform(0.3, 1.0, size=(n, 11)).astype(np.float32)
    bearing = rng.uniform(-math.pi, math.pi, size=n)
    obs[:, 9], obs[:, 10] = np.sin(bearing), np.cos(bearing)
    turns = NavConfig().robot.turns
    gap = np.abs(np.angle(np.exp(1j * (bearing[:, None] - turns[None, :]))))
    return obs, gap.argmin(axis=1)


class Episode:
    """The fields NIRLLearner.add_demos reads from an agents.demos.Demo."""

    def __init__(self, observations, actions):
        self.observations = observations
        self.actions = actions
        self.terminations = np.zeros(len(actions), bool)
        self.truncations = np.zeros(len(actions), bool)
        self.truncations[-1] = True


def refinement_rates(learner, recorded, expert) -> tuple[float, float]:
    """(share of injected steps relabelled to the expert's action, share of clean steps kept)."""
    steps, refined = learner.refine_all()
    n = len(steps)  # episode e holds rows 20 e .. 20 e + 19: stored step i is row i
    assert torch.equal(steps["action"], torch.as_tensor(recorded[:n]))
    wrong = torch.as_tensor(recorded[:n] != expert[:n])
    labels = refined.labels
    relabelled = (labels[wrong] == torch.as_tensor(expert[:n])[wrong]).float().mean()
    kept = (labels[~wrong] == steps["action"][~wrong]).float().mean()
    return float(relabelled), float(kept)


def test_gather_draws_the_rows_torchrls_sample_draws():
    """agents.nirl.buffers.gather reads the storage's columns at the indices the buffer's own sampler
    draws: the same rows as TorchRL's ``buffer.sample`` from the same generator state, draw after
    draw, only the keys asked for, and a TensorDict of them through ``sample``."""
    from tensordict import TensorDict

    from agents.nirl.buffers import demo_buffer, gather, sample

    n = 300
    rows = TensorDict(
        {
            "observation": torch.randn(n, 11),
            "action": torch.randint(0, 5, (n,)),
            "noise": torch.rand(n),
            "next": {"observation": torch.randn(n, 11), "terminated": torch.rand(n, 1) < 0.1},
        },
        batch_size=[n],
    )
    ours, torchrls = demo_buffer(1000, seed=4), demo_buffer(1000, seed=4)
    ours.extend(rows.clone())
    torchrls.extend(rows.clone())
    keys = ("observation", "action", ("next", "observation"), ("next", "terminated"), "to_go")
    for size in (64, 17, 64):
        got, expected = gather(ours, size, keys), torchrls.sample(size)
        assert set(got) == set(keys[:4])  # "to_go" is not held: left out
        for key, value in got.items():
            assert torch.equal(value, expected[key]), key
    whole, expected = sample(ours, 8), torchrls.sample(8)
    assert whole.batch_size == torch.Size([8])
    assert set(whole.keys(True, True)) == set(expected.keys(True, True))
    assert (whole == expected).all()


def test_map_refinement_relabels_injected_noise_and_keeps_clean_steps():
    """30% of the recorded actions replaced by another one (known): MAP refinement must give most
    of them back their expert action and leave the clean ones as they were."""
    obs, expert = goal_seeking_steps(1600, seed=0)
    rng = np.random.default_rng(1)
    injected = rng.random(len(expert)) < 0.3
    shift = rng.integers(1, 5, size=len(expert))
    recorded = np.where(injected, (expert + shift) % 5, expert)
    learner = NIRLLearner(NIRLConfig(**SMALL, warmstart_updates=600, demo_noise=0.3, seed=0))
    episodes = [Episode(obs[i : i + 21], recorded[i : i + 20]) for i in range(0, 1580, 20)]
    learner.add_demos(episodes)
    before = refinement_rates(learner, recorded, expert)
    learner.warm_start()
    relabelled, kept = refinement_rates(learner, recorded, expert)
    assert before == (0.0, 1.0)  # no refinement before refine_start updates
    assert relabelled >= 0.6, relabelled  # 67% when this bar was set (alpha 0.01, prior T 0.002)
    assert kept >= 0.99, kept


def test_without_refinement_every_step_keeps_its_action():
    obs, expert = goal_seeking_steps(42, seed=2)
    learner = NIRLLearner(NIRLConfig(**SMALL, refine=False))
    learner.add_demos([Episode(obs[:21], expert[:20]), Episode(obs[21:42], expert[21:41])])
    steps, refined = learner.refine_all()
    assert torch.equal(refined.labels, steps["action"])
    assert torch.all(refined.weights == 1) and torch.all(refined.decisions == KEEP)


def test_learned_reward_recovers_the_grid_worlds_optimal_policy():
    """IQ-Learn's reward, re-planned alone on the MDP toolkit's grid world, gives back the expert's
    optimal policy on >= 95% of states; the same pipeline fed random actions does not (so the check
    can fail)."""
    from agents.mdp import FiniteMDP, grid_mdp, q_value_iteration
    from agents.nirl.gridcheck import (
        check_reward_recovery,
        expert_transitions,
        iq_learn_tabular,
        optimal_sets,
        policy_agreement,
        recovered_reward,
    )
    from worlds.gridworld import DEFAULT_MAP, GridWorldConfig
    from worlds.maps import parse_ascii

    for seed in (0, 1):
        result = check_reward_recovery(episodes=200, gamma=0.99, seed=seed)
        assert result.agreement >= 0.95, result
        assert result.states == 33 and result.demo_transitions > 1000
    grid, markers = parse_ascii(DEFAULT_MAP)
    dynamics, mdp = grid_mdp(grid, markers["G"], GridWorldConfig(slip=0.1), gamma=0.99)
    optimal = optimal_sets(q_value_iteration(mdp, eps=1e-8).q)
    random_policy = np.random.default_rng(0).integers(0, mdp.n_actions, size=mdp.n_states)
    data = expert_transitions(
        mdp, random_policy, dynamics.goal_state, 50, np.random.default_rng(0), max_steps=40
    )
    q = iq_learn_tabular(mdp.n_states, mdp.n_actions, data, 0.99, steps=1000)
    replanned = q_value_iteration(
        FiniteMDP(list(mdp.transitions), recovered_reward(mdp, q, dynamics.goal_state, 0.05), 0.99)
    )
    assert policy_agreement(replanned.policy, optimal, dynamics.goal_state) < 0.6


@pytest.mark.slow
@pytest.mark.timeout(1200)  # three short runs: about 1 min on a quiet machine, 6+ on a loaded one
def test_nirl_from_5_demos_on_a_tiny_map_reaches_the_goal_across_seeds(tmp_path):
    from agents.evaluation.policies import load_policy
    from agents.nirl.train_local import train_nirl
    from agents.planning.demonstrate import generate_demos
    from worlds.env import NavigationEnv
    from worlds.outcomes import Outcome

    tiny = tmp_path / "tiny.txt"
    tiny.write_text(TINY_MAP)  # S and G markers: one fixed task
    nav = NavConfig(pool_size=1)
    env = NavigationEnv(nav, maps=str(tiny))
    successes = []
    for seed in range(3):
        demos, _ = generate_demos(str(tiny), 5, seed=seed, config=nav)
        assert len(demos) == 5
        config = NIRLConfig(
            **SMALL,
            warmstart_updates=200,
            iterations=12,
            steps_per_iteration=384,
            reward_updates=20,
            q_updates=512,  # half the default per round, as 128 was of 256 (issue 15 part 3: 1,024)
            temperature_decay_iterations=12,
            seed=seed,
        )
        out = tmp_path / f"run{seed}"
        run = NIRLRun(
            envs=8, maps=str(tiny), out=str(out), eval_every=0, final_eval_episodes=0, progress=False,
            tensorboard=str(tmp_path / f"tb{seed}"),
        )  # fmt: skip
        result = train_nirl(demos, config, run, nav)
        assert result.env_steps == 12 * 384 and result.learner.iteration == 12
        policy = load_policy(out)  # the saved greedy policy, as `navlearn evaluate` loads it
        assert policy.model == "nirl" and policy.kind == "q_network"
        outcomes = []
        for episode in range(20):
            obs, _ = env.reset(seed=1000 * seed + episode)
            done, info = False, {}
            while not done:
                obs, _, terminated, truncated, info = env.step(int(policy(obs[None])[0]))
                done = terminated or truncated
            outcomes.append(info["outcome"])
        successes.append(sum(o == Outcome.GOAL for o in outcomes))
        point = result.curve[-1]
        for name in ("nirl/learned_reward", "nirl/path_length", "nirl/path_return", "nirl/expert_value"):
            assert math.isfinite(point[name]), name
        assert any((tmp_path / f"tb{seed}").iterdir())  # TensorBoard events written
    for name in (
        "weights_history.safetensors",
        "weights.png",
        "curve.jsonl",
        "summary.json",
        "reward.safetensors",
    ):
        assert (out / name).is_file()
    # every seed, not one lucky one. Behaviour cloning on the same demonstrations solved 9, 11 and 13
    # of these 20 episodes per seed; NIRL solved 16, 11 and 15 when this bar was set. Issue 15 part 3
    # (2026-12-02): 15, 13 and 20 with the reward fixed after 5 rounds (progress shaping); IQ-Learn
    # throughout with the same 512 updates per round 16, 7 and 16; 128 updates per round 0, 2, 17
    assert min(successes) >= 10 and sum(successes) >= 36, successes


def test_checkpoint_and_weight_history_round_trip(tmp_path):
    from agents.nirl.weights import WeightHistory, plot_weight_changes

    obs, expert = goal_seeking_steps(84, seed=3)
    # the reward still learning after one round (the default fixes it after round 1); the plain MLP
    config = NIRLConfig(
        **SMALL, warmstart_updates=10, q_updates=4, reward_updates=2, fix_reward_after=5, network="mlp"
    )
    learner = NIRLLearner(config)
    learner.add_demos([Episode(obs[:42], expert[:41]), Episode(obs[42:], expert[42:83])])
    learner.add_experience(
        {"obs": obs[:80], "action": expert[:80], "reward": np.zeros(80), "next_obs": obs[1:81],
         "terminated": np.zeros(80, bool), "truncated": np.zeros(80, bool)}
    )  # fmt: skip
    history = WeightHistory()
    for _ in range(14):  # 10 warm-start updates, then one iteration of 4 Q updates (2 reward fits)
        learner.update()
    history.record(0, reward=learner.reward_weights(), policy=learner.get_weights())
    assert learner.warm_updates == 10 and learner.iteration == 1 and learner.reward_steps == 2
    learner.save_checkpoint(tmp_path / "ckpt")
    restored = NIRLLearner(config)
    restored.load_checkpoint(tmp_path / "ckpt")
    assert len(restored.demos) == len(learner.demos) == 82
    assert (restored.version, restored.iteration, restored.warm_updates) == (14, 1, 10)
    for name, value in learner.get_weights().items():
        assert np.array_equal(restored.get_weights()[name], value)
    for name, value in learner.reward_weights().items():
        assert np.array_equal(restored.reward_weights()[name], value)
    probe = torch.as_tensor(obs[:16])
    for one in (learner, restored):  # the fit's target network is the loss's target parameters
        loss = one.q.loss
        with torch.no_grad(), loss.target_value_network_params.to_module(loss.value_network):
            expected = one.q.network(probe)  # the network run on the target parameters
        assert not torch.equal(expected, one.q.network(probe))  # 14 soft updates behind, not the net
        assert torch.equal(one.fit.target_q(probe), expected)
    named = r"dueling head \(dueling=True\).*NIRLConfig\(dueling=True\) \(--dueling\)"
    with pytest.raises(ValueError, match=named):
        NIRLLearner(NIRLConfig(**SMALL, dueling=False)).load_checkpoint(tmp_path / "ckpt")
    learner.update()
    history.record(1, reward=learner.reward_weights(), policy=learner.get_weights())
    history.save(tmp_path / "history.safetensors")
    loaded = WeightHistory.load(tmp_path / "history.safetensors")
    assert loaded.iterations == [0, 1] and set(loaded.snapshots) == set(history.snapshots)
    changes = loaded.layer_changes("policy")
    assert set(changes) == {"0.weight", "2.weight", "4.weight"}
    assert all(c["step"][1] > 0 and c["drift"][0] == 0 for c in changes.values())
    assert plot_weight_changes(loaded, tmp_path / "w.png").stat().st_size > 10_000


def test_old_max_margin_state_loads_and_a_mismatched_core_is_refused(tmp_path):
    """A checkpoint from before cores existed (format 1: no ``format``, no ``core``, reward network
    without ``output``) loads into the max-margin core and is refused, naming the fix, by IQ-Learn."""
    obs, expert = goal_seeking_steps(42, seed=4)
    old = NIRLLearner(NIRLConfig(**SMALL, core="max_margin", gamma=0.95, warmstart_updates=3))
    old.add_demos([Episode(obs[:21], expert[:20])])
    old.warm_start()
    old.save_checkpoint(tmp_path / "ckpt")
    state = torch.load(tmp_path / "ckpt" / "nirl.pt", weights_only=True)
    del state["format"], state["config"]["core"], state["config"]["refine_start"], state["config"]["alpha"]
    del (
        state["config"]["chi2_alpha"],
        state["reward_architecture"]["output"],
        state["counters"]["demo_path_steps"],
    )
    torch.save(state, tmp_path / "ckpt" / "nirl.pt")
    config = NIRLConfig.from_dict(state["config"])
    assert config.core == "max_margin" and config.gamma == 0.95
    restored = NIRLLearner(config)
    restored.load_checkpoint(tmp_path / "ckpt")
    for name, value in old.reward_weights().items():
        assert np.array_equal(restored.reward_weights()[name], value)
    with pytest.raises(ValueError, match="core='max_margin'"):
        NIRLLearner(NIRLConfig(**SMALL)).load_checkpoint(tmp_path / "ckpt")


def test_a_fixed_reward_stays_fixed_through_a_checkpoint():
    learner = NIRLLearner(NIRLConfig())
    learner.fix_reward()
    restored = NIRLLearner(NIRLConfig())
    assert not restored.reward_fixed
    load_nirl_state(restored, nirl_state(learner))
    assert restored.reward_fixed
    assert not any(p.requires_grad for p in restored.reward.parameters())
    with pytest.raises(ValueError, match="max_margin"):
        NIRLLearner(NIRLConfig(core="max_margin")).fix_reward()


def test_a_potential_saved_on_other_inputs_is_refused_naming_the_setting():
    """The potential's inputs are part of its shape: a state whose potential read every feature (or was
    saved before ``potential_inputs`` existed, when it always did) is refused by the default learner
    (goal features) with the setting that loads it, and loads with that setting."""
    saved = NIRLLearner(NIRLConfig(potential_inputs="observation"))
    state = nirl_state(saved)
    with pytest.raises(ValueError, match="potential_inputs='observation'"):
        load_nirl_state(NIRLLearner(NIRLConfig()), state)
    del state["config"]["potential_inputs"]
    assert NIRLConfig.from_dict(state["config"]).potential_inputs == "observation"
    with pytest.raises(ValueError, match="--potential-inputs observation"):
        load_nirl_state(NIRLLearner(NIRLConfig()), state)
    restored = NIRLLearner(NIRLConfig(potential_inputs="observation"))
    load_nirl_state(restored, state)
    for name, value in saved.potential.state_dict().items():
        assert torch.equal(restored.potential.state_dict()[name], value)

"""NIRL hyper-parameters (NIRLConfig, one flat dataclass, cleanrl-style) and the local run's settings
(NIRLRun: environment, evaluation, outputs of ``navlearn nirl train``)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from agents.mlp import ACTIVATION_NAMES
from agents.nnql.config import NETWORKS, LocalConfig, NNQLConfig
from worlds.config import TRAINING_DISCS

CORES = ("iq", "sqil", "max_margin")
FIXED_REWARDS = ("network", "progress")
POTENTIAL_INPUTS = ("observation", "goal")
REFINE_PRIORS = ("policy", "hindsight")
FORMAT_VERSION = 2
"""saved-state format: 1 = the first, max-margin learner (no ``core`` field, gamma 0.95), 2 = cores"""


@dataclass
class NIRLConfig:
    """Neural inverse RL: Q-network policy and reward, MAP refinement, policy iteration (see agents.nirl).

    The Q-learning machinery (network, replay, optimiser, target network) is NNQL's;
    ``nnql_config()`` hands the matching NNQLConfig to ``agents.nnql.learner.NNQLLearner``.
    """

    core: str = "iq"
    """how the reward is learned: iq (inverse soft-Q learning, Garg et al. 2021: the default), sqil
    (SQIL's fixed 1/0 rewards, Reddy et al. 2020: a baseline) or max_margin (the thesis-era fit:
    a reward network by maximum margin planning, then Q-learning under it)"""
    hidden_sizes: tuple[int, ...] = (128, 128)
    """widths of the Q-network's hidden layers (the policy is softmax(Q / alpha))"""
    activation: str = "relu"
    """hidden activation of both networks: relu, tanh or elu"""
    dueling: bool = True
    """dueling head on the Q-network (NNQL's default, Wang et al. 2016): V(s) + A(s, a) - mean A, so the
    state's value and the ranking of its actions are fitted apart. On the validation seed (20 clean demos,
    100 rounds with discs, 500 + 500 episodes, one seed) 94.2% / 82.8% against the plain head's 91.8% /
    81.4%; on the test seed at 200 rounds, 3 seeds, level with the plain head (docs/notebook.md, issue 15
    part 7). Saved configs without the field had the plain head"""
    network: str = field(default="auto", metadata={"choices": NETWORKS})
    """the Q-network variant, as NNQLConfig.network (auto: on NIRL's observations, local, the default
    since issue 39; mlp: the MLP alone). With local, one small MLP shared by the actions over the 2K+1
    range readings around each action's heading and the goal turned to it is added to that action's Q
    (agents.nnql.action_local): with gamma 0.98 and part 14's setting, 90% validation at a median 81,920
    robot-steps against the MLP's 143,360 (docs/notebook.md, issue 15 part 15)"""
    local: LocalConfig = field(default_factory=LocalConfig)
    """network local's own settings, as NNQLConfig.local"""
    reward_hidden_sizes: tuple[int, ...] = (64, 64)
    """widths of the reward network's hidden layers (input: state-action features)"""
    reward_scale: float = 2.0
    """max_margin: the learned reward is a cost in (-reward_scale, 0); iq/sqil: unused"""
    gamma: float = 0.98
    """discount factor (NNQL's 0.98, a 50-step horizon: with the action-local branch it reached 90% validation
    sooner than 0.99, issue 15 part 15; the default since issue 39)"""
    alpha: float = 0.01
    """iq/sqil: entropy temperature of the soft Q-function; V = alpha logsumexp(Q / alpha)"""
    chi2_alpha: float = 0.5
    """iq: chi-squared regulariser E[r^2] / (4 chi2_alpha); a demonstrated step earns about 2 chi2_alpha"""
    crash_absorbing: bool = True
    """absorbing end states (DAC): iq: a collision leads to one valued at IQ-Learn's optimum there (not
    to nothing); sqil: the goal is an expert absorbing state (reward 1 forever), a collision earns 0"""
    crash_clip: float = 0.0
    """iq: weight of a squared hinge (over the chi-squared scale 1 / (4 chi2_alpha)) that keeps the implicit
    reward of the learner's own crash steps at or below the batch's mean demonstrated reward
    (losses.crash_clip_loss); 0 disables it"""
    fix_reward_after: int = 1
    """iq: after this many iterations the learned reward is fixed and the Q-network learns by soft
    Q-learning on it (NNQL policy iteration on the learned reward, ``fixed_reward``); 0: IQ-Learn
    throughout. 1 (issue 15 part 14's choice on the validation seed, part 15's setting) is the default"""
    fixed_reward: str = "progress"
    """iq, once the reward is fixed: the reward the Q-network learns on - network (the reward network
    distilled from IQ-Learn's implicit reward) or progress (a unit step cost shaped by a progress
    potential regressed on the demonstrations' steps to go, agents.nirl.progress)"""
    potential_inputs: str = "goal"
    """fixed_reward=progress: what the progress potential regresses on - goal (the default: the features
    after the range readings, in LEARNING_NAV the goal's and the subgoal's distance and bearing, in
    LEARNING_PLAN_NAV also the own map's plan length; one frame, no patch: agents.nirl.learner checks)
    or observation (every feature). Goal predicts an unseen expert's steps to go better than every
    feature does (fewer inputs to overfit 20 demonstrations; results/nirl/scripts/nirl_potential.py)"""
    policy_steps: int = 0
    """iq with fixed_reward=progress: robot-steps of NNQL's own local trainer (many robots, its utd,
    dueling head, moving-disc mix, keep-best) on the fixed learned reward once IQ-Learn's
    ``fix_reward_after`` rounds are done, instead of NIRL's own soft Q-learning rounds
    (agents.nirl.policy_iteration); 0: NIRL's rounds go on (``iterations``)"""
    policy_utd: float = 0.0
    """update-to-data ratio of that phase (0: NNQL's default)"""
    policy_warm_start: int = 0
    """with policy_steps: rounds of NIRL's own soft Q-learning on the fixed reward (demonstrations in every
    batch) after ``fix_reward_after``, whose Q-network then starts NNQL's trainer - its output scaled by
    ``1 - gamma`` into the phase's reward units, exploring from ``policy_temperature``; 0: NNQL's trainer
    starts from a fresh network at its own exploration schedule"""
    policy_temperature: float = 0.01
    """with policy_warm_start: the warm-started phase's Boltzmann temperature (constant; NNQL's
    schedule ends at 0.01, its start of 0.2 would forget the demonstrated policy while Q settles)"""
    lr: float = 1e-3
    """Adam learning rate of the Q-network"""
    reward_lr: float = 1e-3
    """Adam learning rate of the reward network"""
    reward_weight_decay: float = 1e-4
    """L2 penalty on the reward network (the regulariser of maximum margin planning)"""
    margin: float = 0.5
    """max_margin: a demonstrated action must beat action a by margin * (0.5 + 0.5 * turn gap)"""
    rank_coef: float = 1.0
    """max_margin: weight of the ranking margin (demonstrated steps out-score the learner's own)"""
    q_margin_coef: float = 0.5
    """max_margin: weight of the large-margin term on the Q-network's values at demo states"""
    refine: bool = True
    """MAP refinement of demonstrations (False: every demonstrated action kept with weight 1)"""
    refine_start: int = 500
    """Q updates fitted to the recorded actions before MAP refinement starts (EM needs a trained prior:
    an untrained one relabels at random and its own relabels then confirm it)"""
    demo_noise: float = 0.1
    """probability that a demonstrated action is a random one (MAP refinement's observation noise), for
    demonstrations whose dataset does not record it (a recorded ``noise``, 0 for a clean expert, wins)"""
    prior_temperature: float = 0.002
    """temperature of the policy prior softmax(Q / T) of MAP refinement: alpha / 5, sharper than the
    policy, as a policy fitted to noisy steps spreads the noise over every action and explains it away"""
    relabel_threshold: float = 0.9
    """relabel a demonstrated step to the MAP action when that action's posterior reaches this"""
    refine_prior: str = "policy"
    """MAP refinement's prior over intended actions: policy (the Q-network's softmax, learned beside the
    noisy steps; the settings above) or hindsight (agents.nirl.hindsight: the lattice A* on the map the
    demonstration's own range readings drew, settings ``HindsightSettings``; computed once per episode
    when it is added; needs ``agents.demos.Demo`` episodes with poses, so not the distributed learner's).
    The policy prior, fitted beside the noisy steps, is rarely sure enough to relabel; hindsight
    catches far more of the injected actions while keeping the clean ones
    (results/nirl/nirl_hindsight_measure.json)"""
    batch_size: int = 128
    """transitions per Q update (demonstrated plus own)"""
    demo_fraction: float = 0.5
    """share of each update's batch drawn from the demonstrations (IQ-Learn and SQIL: 50/50)"""
    demo_batch_size: int = 128
    """max_margin: demonstration steps per reward update and per margin term"""
    replay_capacity: int = 100_000
    """experience replay size in transitions"""
    demo_capacity: int = 200_000
    """demonstration steps kept (own buffer: experience never evicts demonstrations)"""
    warmstart_updates: int = 500
    """updates on the demonstrations alone (offline IQ-Learn) before the first iteration"""
    iterations: int = 100
    """policy-iteration rounds of the local trainer (100 = 204,800 robot-steps: part 15's setting)"""
    steps_per_iteration: int = 2_048
    """environment steps collected with the current stochastic policy per iteration (local trainer)"""
    reward_updates: int = 50
    """reward-network updates per iteration (iq/sqil: regression on the Q-function's implicit reward)"""
    q_updates: int = 512
    """Q-network updates per iteration (512 per 2,048 robot-steps, parts 8-15's setting; 256 left policy
    evaluation short: 77.3% against 85.7% validation success, 20 clean demos, seed 0, docs/notebook.md
    issue 15 part 3)"""
    temperature_start: float = 0.05
    """Boltzmann temperature of the behaviour policy at iteration 0 (0.05 and 0.01: more exploration,
    chosen on the validation seed in issue 15 part 14)"""
    temperature_end: float = 0.01
    """... after temperature_decay_iterations (geometric decay)"""
    temperature_decay_iterations: int = 30
    """iterations over which the temperature decays"""
    target_tau: float = 0.05
    """Polyak factor of the Q target network (0.005 propagated values along 30-step paths too slowly)"""
    double_q: bool = True
    """max_margin: double Q-learning in policy evaluation"""
    grad_clip: float = 10.0
    """max global gradient norm of each network's update (0 disables clipping)"""
    seed: int = 0
    """seeds both networks, replay sampling and the local trainer's environments"""
    torch_threads: int = 1
    """torch intra-op threads"""

    def __post_init__(self) -> None:
        self.hidden_sizes = tuple(int(h) for h in self.hidden_sizes)
        self.reward_hidden_sizes = tuple(int(h) for h in self.reward_hidden_sizes)
        if self.core not in CORES:
            raise ValueError(f"NIRLConfig.core={self.core!r}: expected one of {CORES}")
        if self.potential_inputs not in POTENTIAL_INPUTS:
            raise ValueError(
                f"NIRLConfig.potential_inputs={self.potential_inputs!r}: expected one of {POTENTIAL_INPUTS}"
            )
        if self.fixed_reward not in FIXED_REWARDS:
            raise ValueError(f"NIRLConfig.fixed_reward={self.fixed_reward!r}: expected {FIXED_REWARDS}")
        if self.alpha <= 0 or self.chi2_alpha <= 0:
            raise ValueError(
                f"NIRLConfig: need alpha > 0 and chi2_alpha > 0, got {self.alpha}, {self.chi2_alpha}"
            )
        if self.activation not in ACTIVATION_NAMES:
            raise ValueError(f"NIRLConfig.activation={self.activation!r}: expected one of {ACTIVATION_NAMES}")
        if not self.hidden_sizes or not self.reward_hidden_sizes:
            raise ValueError("NIRLConfig: both networks need at least one hidden layer")
        if min(*self.hidden_sizes, *self.reward_hidden_sizes) < 1:
            raise ValueError("NIRLConfig: hidden layer widths must be positive")
        if not 0.0 < self.gamma < 1.0:
            raise ValueError(f"NIRLConfig.gamma={self.gamma}: expected 0 < gamma < 1")
        if self.reward_scale <= 0 or self.margin < 0 or min(self.q_margin_coef, self.rank_coef) < 0:
            raise ValueError(
                "NIRLConfig: need reward_scale > 0 and non-negative margin, rank_coef, q_margin_coef"
            )
        if not 0.0 <= self.demo_noise < 1.0:
            raise ValueError(f"NIRLConfig.demo_noise={self.demo_noise}: expected 0 <= noise < 1")
        if self.refine_prior not in REFINE_PRIORS:
            raise ValueError(f"NIRLConfig.refine_prior={self.refine_prior!r}: expected {REFINE_PRIORS}")
        if not 0.0 < self.relabel_threshold <= 1.0 or self.prior_temperature <= 0:
            raise ValueError("NIRLConfig: need 0 < relabel_threshold <= 1 and prior_temperature > 0")
        if not 0.0 <= self.demo_fraction < 1.0:
            raise ValueError(f"NIRLConfig.demo_fraction={self.demo_fraction}: expected 0 <= f < 1")
        if min(self.batch_size, self.demo_batch_size) < 1 or self.replay_capacity < self.batch_size:
            raise ValueError("NIRLConfig: need positive batch sizes and replay_capacity >= batch_size")
        if min(self.temperature_start, self.temperature_end) <= 0:
            raise ValueError("NIRLConfig: Boltzmann temperatures must be > 0")
        if isinstance(self.local, dict):  # from a saved config
            self.local = LocalConfig(**self.local)
        if self.network not in NETWORKS or self.network in ("patch", "cnn"):
            raise ValueError(
                f"NIRLConfig.network={self.network!r}: expected auto, local or mlp (NIRL's observations,"
                " learning and learning_plan, have no own-map patch and are no image)"
            )
        if min(self.iterations, self.steps_per_iteration, self.reward_updates, self.q_updates) < 0:
            raise ValueError("NIRLConfig: iteration counts must be >= 0")
        if self.policy_steps < 0 or self.policy_utd < 0:
            raise ValueError("NIRLConfig: need policy_steps >= 0 and policy_utd >= 0")
        if self.policy_warm_start < 0:
            raise ValueError(f"NIRLConfig.policy_warm_start={self.policy_warm_start}: expected >= 0 rounds")
        if self.policy_warm_start and self.network != "mlp":
            raise ValueError(
                f"NIRLConfig.policy_warm_start={self.policy_warm_start} hands NIRL's Q-network to NNQL's "
                f"trainer in the plain MLP's layout, which network={self.network!r} does not have: add "
                "--network mlp"
            )
        if self.policy_temperature <= 0:
            raise ValueError(f"NIRLConfig.policy_temperature={self.policy_temperature}: expected > 0")
        fixed = self.core == "iq" and self.fixed_reward == "progress" and self.fix_reward_after > 0
        if self.policy_steps and not fixed:
            raise ValueError(
                "NIRLConfig.policy_steps: needs core iq, fixed_reward progress, fix_reward_after > 0"
            )

    def nnql_config(self) -> NNQLConfig:
        """The NNQL configuration of the Q-learning machinery NIRL's policy evaluation reuses."""
        return NNQLConfig(
            hidden_sizes=self.hidden_sizes,
            activation=self.activation,
            dueling=self.dueling,
            network=self.network,
            local=self.local,
            lr=self.lr,
            gamma=self.gamma,
            batch_size=self.batch_size,
            replay_capacity=self.replay_capacity,
            learning_starts=self.batch_size,
            target_update="soft",
            target_tau=self.target_tau,
            double_q=self.double_q,
            grad_clip=self.grad_clip,
            exploration="boltzmann",
            temperature_start=self.temperature_start,
            temperature_end=self.temperature_end,
            seed=self.seed,
            torch_threads=self.torch_threads,
        )

    def own_rounds(self) -> int:
        """NIRL's own rounds: ``iterations``, or with ``policy_steps`` those before NNQL's trainer takes
        over (IQ-Learn's ``fix_reward_after``, then ``policy_warm_start`` on the fixed reward)."""
        if not self.policy_steps:
            return self.iterations
        return min(self.iterations, self.fix_reward_after + self.policy_warm_start)

    def temperature_at(self, iteration: int) -> float:
        """Behaviour-policy temperature at ``iteration`` (geometric decay from start to end)."""
        frac = min(max(iteration, 0) / max(self.temperature_decay_iterations, 1), 1.0)
        return float(self.temperature_start * (self.temperature_end / self.temperature_start) ** frac)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able copy (tuples become lists)."""
        data = dataclasses.asdict(self)
        data["hidden_sizes"] = list(self.hidden_sizes)
        data["reward_hidden_sizes"] = list(self.reward_hidden_sizes)
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> NIRLConfig:
        """Inverse of to_dict; unknown keys are an error so typos do not pass silently. A field a saved
        config lacks reads as what it meant then (:data:`SAVED_WITHOUT`), not as today's default."""
        data = dict(data)
        if "network" not in data:  # saved with ``action_local`` (k > 0: the branch), or before it: none
            window = int(data.pop("action_local", 0))
            data |= {"network": "local", "local": {"window": window}} if window else {"network": "mlp"}
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ValueError(f"NIRLConfig: unknown field(s) {unknown}")
        return cls(**(SAVED_WITHOUT | data))


SAVED_WITHOUT = {"core": "max_margin", "potential_inputs": "observation", "dueling": False}
"""what a saved NIRL config (a checkpoint's, a policy's config.json) without the field meant: saved
before cores existed (format 1), it was the max-margin learner's; before ``potential_inputs`` existed,
the potential read every feature; before ``dueling`` existed, the Q-network had a plain head. Saved
before ``network``, its ``action_local`` k > 0 was the action-local branch of window k, 0 (or none)
the MLP alone"""


@dataclass
class NIRLRun:
    """Environment, evaluation and outputs of one local NIRL run (the algorithm is NIRLConfig's)."""

    envs: int = 16
    """robots stepped together when collecting experience"""
    maps: str = "mixed:16"
    """map spec of the experience-collection maps (worlds.tasks.parse_map_spec: generated, or map files
    such as a map_server .yaml; docs/maps.md)"""
    moving_discs: int = TRAINING_DISCS
    """NIRL's own rounds: each experience episode has 0..moving_discs moving discs (default 0..6, NNQL's
    mix and part 15's setting; 0: none; NNQL's trainer in the policy_steps phase has its own 0..6 mix)"""
    out: str = "runs/nirl"
    """output directory: policy files, weights_history.safetensors, curve.jsonl, summary.json"""
    eval_every: int = 5
    """iterations between greedy evaluations on held-out maps (0: only the final one)"""
    eval_episodes: int = 50
    """episodes of each periodic evaluation ("unseen" family, validation seed)"""
    keep_best: bool = False
    """NIRL's own rounds: the policy is the Q-network that scored best on the periodic evaluations (the
    last round's included; ties go to the later) instead of the last one - NNQL's keep_best. Off by
    default: on episodes it did not choose on, the round it kept from 100 static episodes every 10
    rounds did worse than the last (a winner's curse of small evaluations). Needs eval_every > 0; the
    policy_steps phase keeps its own best"""
    average_last: float = 0.25
    """NIRL's own rounds: the policy is the Q-network's weights averaged over this fraction of the rounds
    at the end (stochastic weight averaging along the rounds, Izmailov et al. 2018; 200 rounds: the last
    50), against the round-to-round swing of the greedy policy; 0: the last round's. keep_best, when
    on, wins"""
    final_eval_episodes: int = 100
    """episodes of the final evaluation ("unseen" family, seed 0: the reported set)"""
    tensorboard: str = ""
    """TensorBoard log directory (empty: none): losses, nirl/learned_reward, path length, collision value"""
    progress: bool = True
    """show a progress bar"""
    device: str = "cpu"
    """where the learner's networks, losses and sampled batches live: cpu, cuda (cuda:N) or auto"""
    policy_eval_every: int = 25_000
    """NIRLConfig.policy_steps > 0: robot-steps between validation evaluations of the NNQL phase (keep-best's
    candidates; 0: none, the last weights are kept)"""
    policy_eval_dynamic_episodes: int = 0
    """... and episodes with 4 moving discs added to each of them (keep-best then scores both sets)"""

    def __post_init__(self) -> None:
        if not 0.0 <= self.average_last <= 1.0:
            raise ValueError(f"NIRLRun.average_last={self.average_last}: expected a fraction in [0, 1]")

    def averaged_rounds(self, rounds: int) -> int:
        """How many of ``rounds`` own rounds the policy averages (0: none, the last round's)."""
        return min(rounds, round(rounds * self.average_last)) if rounds else 0

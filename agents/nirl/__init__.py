"""Neural inverse reinforcement learning, NIRL (thesis ch. 5): a library, no transport.

The thesis frame, kept
----------------------
Xia (2015, ch. 5) and Xia & El Kamel (RAS 84, 2016) describe NIRL by its parts: a neural
network represents the expert's stochastic policy so it generalises to states no demonstration
visited; a reward is learned from the demonstrations; MAP-based refinement of sub-optimal
demonstrations; neural policy iteration on the learned reward, which largely reduces learning
time compared with learning from scratch; maximum margin planning. Their exact equations are
not available to us; what follows is our choice inside that frame.

The inverse-RL core: IQ-Learn (default, ``NIRLConfig.core = "iq"``)
--------------------------------------------------------------------
Inverse soft-Q learning (Garg, Chakraborty, Cundy, Song & Ermon, "IQ-Learn: Inverse soft-Q
Learning for Imitation", NeurIPS 2021, arXiv:2106.12142). One soft Q-function holds both the
reward and the policy: the policy is ``pi(a|s) = softmax(Q(s, .) / alpha)`` (the thesis'
Boltzmann policy over NNQL's Q-network) and the reward is what the inverse soft Bellman
operator reads out of it, ``r(s, a, s') = Q(s, a) - gamma V(s')`` with
``V(s) = alpha logsumexp(Q(s, .) / alpha)``. IQ-Learn maximises, over Q alone, the
inverse-RL objective with a chi-squared divergence,
``E_expert[r] - E_rho[V(s) - gamma V(s')] - E[r^2] / (4 chi2_alpha)`` (``losses.iq_loss``),
on 50/50 batches of demonstrated steps and the learner's own replayed experience: the expert
term raises the reward of demonstrated steps, the value term lowers the value of states the
learner reaches without the expert (collisions end an episode with nothing after them), the
regulariser bounds the reward (a demonstrated step earns about ``2 chi2_alpha``). Each update
is one step of soft policy iteration: policy evaluation under the reward the Q-function
currently holds, policy improvement by the softmax over the new Q.

Why this core: (1) the reward really is learned from the demonstrations and drives the policy
through policy iteration - the earlier max-margin learner (``--core max_margin``) was in effect an
action scorer plus behaviour cloning; (2) IQ-Learn is non-adversarial (no discriminator that
never stops) and off-policy, so it reuses NNQL's replay and takes few
environment steps; (3) it has a recovery guarantee for the reward in the tabular case, which we
check where the true reward is known (``gridcheck``: the MDP toolkit's grid world, the expert's
optimal policy recovered on 100% of states by re-planning under the learned reward alone);
(4) its paper reports it ahead of SQIL, ValueDICE, GAIL and behaviour cloning with one to a few
expert trajectories on Atari and MuJoCo tasks. SQIL (Reddy, Dragan & Levine, ICLR 2020: rewards fixed to 1 on
demonstrated and 0 on own steps; ``core = "sqil"``) and DQfD-style demonstration replay
(Hester et al., AAAI 2018; ``bench/nirl.py``) are measured beside it as baselines: they learn no
reward. The reward network (``networks.RewardNetwork`` over state-action features) is the
explicit, transferable model of IQ-Learn's reward: fitted by regression on the Q-function's
implicit reward, logged, and drawn over maps (``reward_map``, `navlearn nirl reward`).

Policy iteration on the fixed learned reward (the defaults)
-----------------------------------------------------------
Why, from a diagnosis on the validation seed (``bench/nirl.py --split validation --diagnose``):
with 256 Q updates per 2,048 robot-steps policy evaluation was cut short (1,024: +8 points on 20
clean demos); the learner's own crash steps earned an implicit reward of +79..+99 against about
-0.3 per demonstrated step (the absorbing target -100 is far from where the Q of crash steps sits);
and the reward does not transfer: on 20 held-out expert episodes (other maps) an expert step earns
-0.67 against -0.07 on the training demonstrations and -0.31 on the learner's own steps, and the
greedy policy agrees with the expert on 69% of held-out steps against 86% of trained ones.
What NIRL now does, each part from the literature:

* IQ-Learn as above for the first ``fix_reward_after`` = 5 rounds, 1,024 Q updates per round, its
  chi-squared regulariser over expert and policy samples (the ``regularize`` option of Garg et al.'s
  code ``iq_learn``), a Polyak target network;
* then the learned reward is fixed and NNQL's policy iteration runs on it: soft Q-learning
  (``losses.soft_td_loss``) on the same 50/50 batches, its reward (``fixed_reward = "progress"``,
  ``agents.nirl.progress``) a unit cost per step shaped by a potential learned from the
  demonstrations - the expert's value at unit step cost, regressed on what the robot perceives:
  potential-based shaping (Ng, Harada & Russell 1999: the optimal policy is unchanged),
  built from demonstrations (Brys et al., IJCAI 2015), a state-only term ``gamma Phi(s') - Phi(s)`` as
  in AIRL (Fu, Luo & Levine 2018), with the collision's absorbing state (DAC, Kostrikov et al. 2019)
  valued as never arriving. ``fixed_reward = "network"`` uses the reward network distilled from
  IQ-Learn instead (measured: it collapsed on the noisy set, 0% validation success);
* ``crash_clip`` (off by default): a squared hinge keeping crash steps' implicit reward at or below
  the demonstrated steps' (it helped the noisy set, hurt the clean one; not adopted).

The environment's reward is never read: the potential's targets are the demonstrations' own step
counts to their end at the goal.

Policy iteration at NNQL's speed (``policy_steps``, ``policy_iteration.py``)
    With ``policy_steps > 0`` the soft Q-learning rounds after ``fix_reward_after`` are replaced by
    NNQL's own local trainer (``agents.nnql.train_local``: 16 robots, NNQL's update-to-data ratio,
    dueling head, the 0..6 moving-disc mix, keep-best on the validation seed) on the fixed reward;
    ``policy_iteration.FixedReward`` computes it where the transitions are made (``train_local``'s
    ``reward`` hook overwrites the env's reward before the replay sees it). Its policy is NIRL's
    (``NIRLResult.policy()``; files in ``<out>/policy_iteration``). ``policy_warm_start = N``
    keeps the demonstrations' head start: NIRL's own rounds go on N rounds on the fixed
    reward (demonstrations in every batch), then NNQL's network starts from that Q-network (output
    times ``1 - gamma``, the same greedy policy in the phase's reward units; ``warm_weights``) at a
    constant Boltzmann temperature ``policy_temperature`` - the warm start of DQfD's pre-training
    (Hester et al., AAAI 2018) without its margin; started fresh, the phase fell from 75-81% to
    40-58% validation success and needed 130-170k robot-steps to climb back.
    ``potential_inputs = "goal"`` regresses the potential on the goal's and the subgoal's distance
    and bearing only: on held-out expert episodes it predicts the steps to go better (error 3.9
    against 5.0 steps) than from every feature, whose 24 range readings it over-fits on 20 paths.

MAP refinement after policy iteration (``refine_progress.py``)
    The same posterior over the intended action, with a prior that never fitted the noisy labels
    (the NNQL phase's Q, which saw the demonstrations only through the potential) and evidence from
    the recorded step's progress under the potential (a random action rarely makes the expert's
    progress); relabelled steps are left out of the steps to go and the potential is re-fitted on them.

The policy (``NIRLRun.average_last``, ``train_local``)
    NIRL's own rounds end with the Q-network's weights averaged over their last quarter (stochastic
    weight averaging, Izmailov et al., UAI 2018, along the rounds rather than along SGD steps): the
    greedy policy's validation success swings 83-94% from round to round around a flat level, and the
    average beat the last round on the validation seed.
    Keep-best on 100 validation episodes (``keep_best``, off) chose worse rounds than the last.

Discount: gamma = 0.99, a 100-step horizon for demonstrated paths of about 31 steps (with
0.95 a long path and a crash were valued alike). Logged beside it, per update:
``nirl/learned_reward`` (per demonstrated step), ``nirl/path_length`` and ``nirl/path_return``
(what a demonstrated path earns at that rate), ``nirl/collision_value`` (Q of a step that crashed:
its whole learned value) and ``nirl/expert_value``.

MAP refinement (``losses.map_posterior``, ``losses.refine_steps``, ``NIRLLearner.refine``)
    Each demonstrated action is a noisy observation of the intended one,
    ``P(a_obs | a*) = (1 - eps) [a_obs = a*] + eps / |A|``, with ``eps`` the noise rate the
    dataset records for that episode (0 for a clean expert: its steps are never changed; the
    config's ``demo_noise`` when unrecorded); the prior is the current policy sharpened
    (``prior_temperature``; a policy fitted to noisy steps spreads the noise over all actions and
    would explain it away). A step is kept, re-weighted by its posterior (the weight of its
    expert term), or relabelled with the MAP action when that action's posterior reaches
    ``relabel_threshold``; refinement starts after ``refine_start`` updates (EM needs a trained
    prior; an untrained one relabels at random and its relabels confirm themselves). That prior
    relabels almost none of the injected noise (0-1.4% on 20 noisy demonstrations): fitted beside
    the noisy steps, it is rarely sure. ``refine_prior = "hindsight"`` (``hindsight.py``) takes the
    prior from the demonstration itself instead: the lattice A* on the map its own range readings
    drew, Boltzmann in the actions' cost-to-go, and replaces a recorded action judged noise with
    posterior >= 0.7 (31-42% of the injected actions relabelled to the expert's, 80% of those that
    cost a detour, 99% of clean steps kept). Computed once per demonstration; local training only
    (the wire carries no poses).

The max-margin fit, kept as an option (``core = "max_margin"``, ``max_margin.py``)
    The thesis-era formulation: a cost network by model-free maximum margin planning
    (Ratliff, Bagnell & Zinkevich 2006), then Q-learning under it with NNQL's DQNLoss.

Modules: config (NIRLConfig, NIRLRun) - networks - losses (pure maths) - buffers (datasets
checked for the learner, demo buffer) - learner (NIRLLearner) - soft_q (the iq and sqil cores) -
max_margin - persistence (policy files, learner state, checkpoints; format 1 files of the
max-margin learner load into that core) -
weights (history and plot) - gridcheck (reward recovery where the reward is known) - reward_map
(`navlearn nirl reward`) - train_local (`navlearn nirl train`) - policy_iteration (the NNQL phase) -
refine_progress (MAP refinement after it) - hindsight (MAP refinement's hindsight prior).
"""

from agents.nirl.config import NIRLConfig

__all__ = ["NIRLConfig"]

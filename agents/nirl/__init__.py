"""Neural inverse reinforcement learning, NIRL (thesis ch. 5): a library, no transport.

What the thesis gives and what is ours
--------------------------------------
Xia (2015, ch. 5) and Xia & El Kamel (RAS 84, 2016) describe NIRL by its parts: a
neural network represents the expert's stochastic policy so it generalises to states
no demonstration visited; MAP-based refinement of sub-optimal demonstrations;
model-free maximum margin planning; neural policy iteration, which largely reduces
learning time compared with learning from scratch. Their exact equations are not
available to us. Everything below is our design, built from that description and the
IRL literature: maximum margin planning (MMP, Ratliff, Bagnell & Zinkevich 2006),
Bayesian and MAP inverse RL (Ramachandran & Amir 2007; Choi & Kim 2011), large-margin
Q-learning from demonstrations (Hester et al. 2018, DQfD) and policy iteration.

Networks (``networks.py``; the Q-network is NNQL's ``QNetwork``)
    * reward ``R(s, a) = -scale * sigmoid(f(phi(s, a)))``, an MLP over state-action
      features ``phi``: the observation, a one-hot action code, the free range along the
      heading the action turns to and the goal bearing from that heading. A cost, as in
      MMP's cost maps, so that reaching the goal (the end of an episode) is worth it.
    * policy ``pi(a | s) = softmax(Q(s, .) / T)``: a stochastic policy over a Q-network.

MAP refinement (``losses.map_posterior``, ``losses.refine_steps``)
    Each demonstrated action is a noisy observation of the action the demonstrator meant:
    ``P(a_obs | a*) = (1 - eps) [a_obs = a*] + eps / |A|``. With the current policy as the
    prior ``P(a* | s) = pi(a* | s)`` (temperature ``prior_temperature``), Bayes' rule gives the
    posterior over ``a*``. A step is kept (the recorded action is the MAP action), re-weighted
    by the posterior of its action, or relabelled with the MAP action when that action's
    posterior reaches ``relabel_threshold``. Refinement runs on every sampled batch, so it
    always uses the newest prior; poor demonstrations weigh less as the policy improves.

Model-free maximum margin planning (``losses.max_margin_loss``, ``losses.ranking_margin_loss``)
    MMP fits costs so the demonstrated behaviour beats every alternative by a structured
    loss. Without a transition model, ours does it at two levels, from samples only:
    (1) per decision: ``Q_theta(s, a) = R_theta(s, a) + C(s, a)``, where the continuation
    ``C = Q - R`` (the discounted value after the step) is the Q-network's estimate from
    replayed experience, held fixed; the structured hinge
    ``max_a [Q_theta(s, a) + L(a_d, a)] - Q_theta(s, a_d)`` with
    ``L(a_d, a) = margin * (0.5 + 0.5 * |turn_a - turn_d| / max gap)`` (0 for ``a = a_d``)
    trains the reward through the immediate term; (2) per trajectory: every demonstrated
    step's reward must beat every step of the learner's own sampled experience by the
    margin (the sampled stand-in for MMP's "demonstrated path vs planned path"). Plus
    MMP's L2 regulariser (Adam weight decay). Collisions are infeasible moves, as obstacles
    are in a planner's model: a collision leads to an absorbing state of value
    ``-scale / (1 - gamma)`` (``losses.absorbing_rewards``); goal and collision
    terminations are told apart from the observation (``networks.goal_reached``).

Neural policy iteration (``learner.NIRLLearner``, ``train_local.train_nirl``)
    Warm start from the demonstrations (the reward by the myopic hinge, ``C = 0``; the
    Q-network by the large-margin loss plus TD on relabelled demo steps), then repeat:
    collect experience with the stochastic policy; reward updates (above); policy
    evaluation = Q-learning with NNQL's machinery (TorchRL replay, DQNLoss with target
    network and double Q) on replayed experience and demonstrations relabelled with the
    learned reward, plus an optional large-margin term at demo states (``q_margin_coef``);
    policy improvement = the softmax over the new Q. The environment's reward is never
    used. The weights of both networks are recorded every iteration (``weights.py``).

Modules: config (NIRLConfig, NIRLRun) - networks - losses (pure maths) - buffers - learner
(NIRLLearner) - persistence (policy files, checkpoints) - weights (history and plot) -
train_local (``navlearn nirl train``).
"""

from agents.nirl.config import NIRLConfig

__all__ = ["NIRLConfig"]

"""The max-margin core (``NIRLConfig.core = "max_margin"``): the thesis-era fit, kept as an option.

A reward network fitted by model-free maximum margin planning (Ratliff, Bagnell & Zinkevich
2006), then Q-learning under it with NNQL's DQNLoss:

* per decision: ``Q_theta(s, a) = R_theta(s, a) + C(s, a)``, the continuation ``C = Q - R``
  held fixed from the Q-network; the structured hinge
  ``max_a [Q_theta(s, a) + L(a_d, a)] - Q_theta(s, a_d)`` trains the reward;
* per trajectory: every demonstrated step's reward must beat every step of the learner's own
  experience by the margin (``losses.ranking_margin_loss``);
* policy evaluation: DQNLoss on replayed experience and demonstrations whose rewards are
  replaced by the learned cost, collisions leading to an absorbing state of value
  ``-scale / (1 - gamma)``, plus a large-margin term on the Q-values at demo states.

What it turned out to be when measured: an action scorer (the hinge) plus a discriminator that never
stops (the ranking term), 49-50% success from 5-20 demonstrations. It is kept so the
thesis' formulation stays runnable and comparable; the default core is IQ-Learn
(``agents.nirl.learner``).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict import TensorDict

from agents.nirl.buffers import sample
from agents.nirl.fit_parts import FitParts
from agents.nirl.losses import (
    KEEP,
    RELABEL,
    REWEIGHT,
    absorbing_rewards,
    margin_violations,
    max_margin_loss,
    ranking_margin_loss,
)
from agents.nirl.networks import goal_reached

Q_KEYS = (
    "observation",
    "action",
    ("next", "observation"),
    ("next", "reward"),
    ("next", "terminated"),
    ("next", "truncated"),
    ("next", "done"),
)


@dataclass(eq=False)
class MaxMarginFit(FitParts):
    """Reward updates by maximum margin planning and Q updates under the learned cost.

    Handed its parts by ``NIRLLearner`` (``FitParts``) and the margin matrix.
    Sampled batches go to the Q-learner's device (as the networks and the margin matrix).
    """

    margins: torch.Tensor
    """(n_actions, n_actions) structured margin L(a_d, a) of the hinge"""

    def reward_step(self, myopic: bool = False) -> dict[str, float]:
        """One maximum-margin update of the reward network on refined demonstration steps
        (``myopic``: the warm start, before any Q exists, uses ``C = 0``)."""
        cfg = self.config
        batch = sample(self.demos, cfg.demo_batch_size, self.q.device)
        obs = batch["observation"]
        refined = self.refine(batch)
        reward = self.reward(obs)
        if myopic:
            q_hat = reward
        else:
            with torch.no_grad():
                continuation = self.q.network(obs) - reward
            q_hat = reward + continuation
        loss = margin = max_margin_loss(q_hat, refined.labels, self.margins, refined.weights)
        rank = torch.zeros(())
        if not myopic and cfg.rank_coef > 0 and len(self.experience):
            own = sample(self.experience, cfg.demo_batch_size, self.q.device)
            own_reward = self.reward(own["observation"]).gather(1, own["action"].long()[:, None])
            demo_reward = reward.gather(1, refined.labels[:, None])
            rank = ranking_margin_loss(demo_reward, own_reward, cfg.margin, refined.weights)
            loss = loss + cfg.rank_coef * rank
        norm = self.clip_step(loss, self.reward.parameters(), self.reward_optimizer)
        decisions = refined.decisions
        return {
            "losses/reward_margin": float(margin.detach()),
            "losses/reward_rank": float(rank.detach()),
            "losses/reward_grad_norm": norm,
            "charts/reward_violations": float(
                margin_violations(q_hat.detach(), refined.labels, self.margins)
            ),
            "charts/demo_reward": float(reward.detach().gather(1, refined.labels[:, None]).mean()),
            "charts/refine_keep": float((decisions == KEEP).float().mean()),
            "charts/refine_reweight": float((decisions == REWEIGHT).float().mean()),
            "charts/refine_relabel": float((decisions == RELABEL).float().mean()),
            "charts/demo_weight": float(refined.weights.mean()),
        }

    def _q_batch(self) -> TensorDict:
        """Experience plus a share of demonstration steps, rewards replaced by the learned cost."""
        cfg = self.config
        n_demo = round(cfg.batch_size * cfg.demo_fraction) if len(self.demos) else 0
        if len(self.experience) == 0:
            n_demo = cfg.batch_size
        parts = []
        if cfg.batch_size - n_demo > 0:
            parts.append(sample(self.experience, cfg.batch_size - n_demo, self.q.device).select(*Q_KEYS))
        if n_demo > 0:
            parts.append(sample(self.demos, n_demo, self.q.device).select(*Q_KEYS))
        batch = torch.cat(parts) if len(parts) > 1 else parts[0]
        with torch.no_grad():
            learned = self.reward(batch["observation"]).gather(1, batch["action"].long()[:, None]).squeeze(1)
        terminated = batch[("next", "terminated")].reshape(-1)
        at_goal = goal_reached(
            batch[("next", "observation")], self.reward.n_beams, self.goal_tolerance, self.max_range
        )
        target_reward = absorbing_rewards(learned, terminated, at_goal, cfg.reward_scale, cfg.gamma)
        batch.set(("next", "reward"), target_reward[:, None])
        return batch

    def q_step(self, margin_coef: float | None = None) -> dict[str, float]:
        """One policy-evaluation update: DQNLoss on relabelled transitions plus (weight
        ``margin_coef``) the large-margin term on the Q-values at refined demo steps."""
        coef = self.config.q_margin_coef if margin_coef is None else margin_coef
        q = self.q
        batch = self._q_batch()
        loss = td_loss = q.loss(batch)["loss"]
        margin = torch.zeros(())
        if coef > 0 and len(self.demos):
            demo = sample(self.demos, self.config.demo_batch_size, self.q.device)
            refined = self.refine(demo)
            margin = max_margin_loss(
                q.network(demo["observation"]), refined.labels, self.margins, refined.weights
            )
            loss = loss + coef * margin
        norm = self.clip_step(loss, q.loss.parameters(), q.optimizer)
        q.lean.update_target()  # SoftUpdate's lerp in one foreach call
        q.updates += 1
        self.after_update()
        return {
            "losses/td_loss": float(td_loss.detach()),
            "losses/q_margin": float(margin.detach()),
            "losses/grad_norm": norm,
            "nirl/learned_reward": float(batch[("next", "reward")].mean()),
            "charts/version": float(q.updates),
        }

    def warm_step(self) -> dict[str, float]:
        return {**self.reward_step(myopic=True), **self.q_step(margin_coef=1.0)}

"""The soft-Q cores (``NIRLConfig.core = "iq"`` or ``"sqil"``): Q updates on mixed batches, the reward fit.

``iq`` trains the Q-network by inverse soft-Q learning (Garg et al. 2021) on batches of refined
demonstration steps and own experience; the reward it holds, ``r = Q(s, a) - gamma V(s')``, is
logged beside what it must value (``reward_scale``) and distilled into the reward network by
regression. ``sqil`` is the SQIL baseline (reward 1 on demonstrated steps, 0 on own ones) on the
same machinery. Sampled batches are moved to the Q-learner's device; the buffers stay on the CPU.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
from tensordict import TensorDict

from agents.nirl.buffers import as_tensordict, gather, sample
from agents.nirl.fit_parts import FitParts
from agents.nirl.hindsight import STORED
from agents.nirl.losses import (
    KEEP,
    RELABEL,
    REWEIGHT,
    crash_absorbing_value,
    crash_clip_loss,
    implicit_reward,
    iq_loss,
    soft_td_loss,
    soft_value,
    sqil_rewards,
)
from agents.nirl.networks import goal_reached
from agents.nirl.progress import ProgressPotential, potential_loss, shaped_progress_reward

BATCH_KEYS = ("observation", "action", ("next", "observation"), ("next", "terminated"))


def absorbing_next(
    cfg, next_value: torch.Tensor, terminated: torch.Tensor, at_goal: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Next-state values and terminations with the absorbing end states of ``cfg`` folded in.

    iq: a collision leads to an absorbing state (Kostrikov et al. 2019, DAC) told apart from the
    goal by the observation, valued at IQ-Learn's optimum there (losses.crash_absorbing_value); it
    no longer counts as a termination (its value is bootstrapped). sqil: the goal where
    demonstrations end is an expert absorbing state (reward 1 forever, 1 / (1 - gamma)); a collision
    ends with reward 0 (without it, ending at the goal is worth less than wandering on at reward 1)."""
    terminated = terminated.reshape(-1).bool()
    if not cfg.crash_absorbing:
        return next_value, terminated
    if cfg.core == "iq":
        crashed = terminated & ~at_goal
        next_value = torch.where(crashed, crash_absorbing_value(cfg.chi2_alpha, cfg.gamma), next_value)
        return next_value, terminated & at_goal
    if cfg.core == "sqil":
        forever = torch.full_like(next_value, 1.0 / (1.0 - cfg.gamma))
        next_value = torch.where(terminated & at_goal, forever, next_value)
        return next_value, terminated & ~at_goal
    return next_value, terminated


@dataclass(eq=False)
class SoftQFit(FitParts):
    """Q updates of the iq or sqil core and the reward network's regression on the implicit reward.

    Handed its parts by ``NIRLLearner`` (``FitParts``, as ``MaxMarginFit`` is) and the demonstrated
    path length.
    """

    path_length: Callable[[], float]
    """mean steps of a demonstrated path (logged beside the learned reward's scale)"""
    potential: ProgressPotential | None = None
    """the progress potential (``NIRLConfig.fixed_reward = "progress"``), None otherwise"""
    potential_optimizer: torch.optim.Optimizer | None = None
    reward_fixed: bool = False
    """iq: the reward network is frozen and the Q-network learns by soft Q-learning on it
    (``NIRLConfig.fix_reward_after``); the reward fit stops"""

    def mixed_batch(self, offline: bool) -> tuple[TensorDict, torch.Tensor]:
        """Demonstration steps and own experience, ``demo_fraction`` of the batch demonstrated
        (all of it offline or while no experience exists), on the Q-learner's device; returns the
        batch and its expert mask."""
        cfg = self.config
        n_demo = cfg.batch_size
        if not offline and len(self.experience):
            n_demo = max(1, round(cfg.batch_size * cfg.demo_fraction))
        n_own = cfg.batch_size - n_demo
        demos = gather(self.demos, n_demo, keys=(*BATCH_KEYS, "noise", *STORED))
        own = gather(self.experience, n_own, keys=BATCH_KEYS) if n_own else {}
        rows = {key: torch.cat([demos[key], own[key]]) if own else demos[key] for key in BATCH_KEYS}
        noise = demos.get("noise", torch.full((n_demo,), cfg.demo_noise))
        rows["noise"] = torch.cat([noise, torch.zeros(n_own)])
        for key in STORED:  # the hindsight refinement of the demonstrated rows (refine_prior hindsight)
            if key in demos:
                rows[key] = torch.cat([demos[key], torch.zeros(n_own, dtype=demos[key].dtype)])
        batch = as_tensordict(rows, cfg.batch_size)
        is_expert = torch.zeros(cfg.batch_size, dtype=torch.bool)
        is_expert[:n_demo] = True
        device = self.q.device
        if device.type == "cpu":
            return batch, is_expert
        return batch.to(device, non_blocking=True), is_expert.to(device, non_blocking=True)

    def target_q(self, obs: torch.Tensor) -> torch.Tensor:
        """Q-values of the target network (DQNLoss's target parameters, Polyak-averaged): the lean
        path's copy of the network on those very parameters (agents/nnql/lean.py), without a
        ``to_module`` swap per call."""
        with torch.no_grad():
            return self.q.lean.target(obs)

    def q_step(self, offline: bool = False) -> dict[str, float]:
        """One Q-network update of the configured core (iq or sqil) on a mixed batch."""
        cfg = self.config
        batch, is_expert = self.mixed_batch(offline)
        obs, next_obs = batch["observation"], batch[("next", "observation")]
        terminated = batch[("next", "terminated")].reshape(-1)
        labels = batch["action"].long().reshape(-1).clone()
        fixed = cfg.core == "iq" and self.reward_fixed
        refined = None
        if not fixed:
            # MAP refinement feeds the IQ-Learn and SQIL terms; once the reward is fixed, TD learns what
            # happened: the recorded action led to next_obs, whatever refinement would relabel it to
            refined = self.refine(batch[is_expert])
            weights = torch.ones(len(labels), device=labels.device)
            labels[is_expert], weights[is_expert] = refined.labels, refined.weights
        q_all = self.q.network(obs)
        q_taken = q_all.gather(1, labels[:, None]).squeeze(1)
        next_value = soft_value(self.target_q(next_obs), cfg.alpha)
        metrics: dict[str, float] = {}
        at_goal = goal_reached(next_obs, self.reward.n_beams, self.goal_tolerance, self.max_range)
        next_value, terminated = absorbing_next(cfg, next_value, terminated, at_goal)
        if fixed:
            # NNQL policy iteration on the learned reward, now frozen: soft Q-learning with r = R(s, a)
            # of the reward network (the absorbing crash state keeps its value), on the recorded actions
            if self.potential is not None:  # the progress reward (agents.nirl.progress): ends folded in
                raw_end = batch[("next", "terminated")].reshape(-1).bool()
                reward = shaped_progress_reward(self.potential, obs, next_obs, raw_end, at_goal, cfg.gamma)
                terminated = raw_end
            else:
                with torch.no_grad():
                    reward = self.reward(obs).gather(1, labels[:, None]).squeeze(1)
            loss = soft_td_loss(q_taken, reward, next_value, terminated, cfg.gamma)
            metrics["losses/td_loss"] = float(loss.detach())
        elif cfg.core == "iq":
            terms = iq_loss(
                q_taken, soft_value(q_all, cfg.alpha), next_value, terminated, is_expert, cfg.gamma,
                cfg.chi2_alpha, weights,
            )  # fmt: skip
            loss, reward = terms.loss, terms.reward
            metrics.update({
                "losses/iq_loss": float(terms.loss.detach()),
                "losses/iq_expert": float(terms.expert_term),
                "losses/iq_value": float(terms.value_term),
                "losses/iq_chi2": float(terms.chi2_term),
            })  # fmt: skip
            if cfg.crash_clip > 0:
                crashed = ~is_expert & batch[("next", "terminated")].reshape(-1).bool() & ~at_goal
                clip = crash_clip_loss(q_taken, next_value, crashed, terms.reward[is_expert], cfg.gamma)
                loss = loss + cfg.crash_clip * clip / (4.0 * cfg.chi2_alpha)
                metrics["losses/crash_clip"] = float(clip.detach())
        else:  # sqil
            loss = soft_td_loss(q_taken, sqil_rewards(is_expert), next_value, terminated, cfg.gamma)
            reward = implicit_reward(q_taken.detach(), next_value, terminated, cfg.gamma)
            metrics["losses/td_loss"] = float(loss.detach())
        norm = self.clip_step(loss, self.q.loss.parameters(), self.q.optimizer)
        self.q.lean.update_target()  # SoftUpdate's lerp in one foreach call
        self.q.updates += 1
        self.after_update()
        metrics.update(self.reward_scale(reward, q_taken.detach(), q_all.detach(), batch, is_expert))
        metrics.update({"losses/grad_norm": norm, "charts/version": float(self.q.updates)})
        if refined is not None:
            decisions = refined.decisions
            metrics.update({
                "charts/refine_keep": float((decisions == KEEP).float().mean()),
                "charts/refine_reweight": float((decisions == REWEIGHT).float().mean()),
                "charts/refine_relabel": float((decisions == RELABEL).float().mean()),
                "charts/demo_weight": float(refined.weights.mean()),
            })  # fmt: skip
        return metrics

    def reward_scale(self, reward, q_taken, q_all, batch, is_expert) -> dict[str, float]:
        """The learned reward beside what it must value: per demonstrated step, what a demonstrated
        path earns at that rate, the path length, and the value of a crash (Q of a collision step)."""
        cfg = self.config
        per_step = float(reward[is_expert].mean())
        length = self.path_length()
        out = {
            "nirl/learned_reward": per_step,
            "nirl/path_length": length,
            "nirl/path_return": per_step * (1 - cfg.gamma**length) / (1 - cfg.gamma),
            "nirl/expert_value": float(soft_value(q_all[is_expert], cfg.alpha).mean()),
        }
        own = ~is_expert
        if own.any():
            out["nirl/learned_reward_own"] = float(reward[own].mean())
            terminated = batch[("next", "terminated")].reshape(-1).bool()
            at_goal = goal_reached(
                batch[("next", "observation")], self.reward.n_beams, self.goal_tolerance, self.max_range
            )
            crashed = own & terminated & ~at_goal
            if crashed.any():
                out["nirl/collision_value"] = float(q_taken[crashed].mean())
                out["nirl/crash_reward"] = float(reward[crashed].mean())
        return out

    def potential_step(self) -> dict[str, float]:
        """One regression step of the progress potential on demonstrated steps (agents.nirl.progress)."""
        if self.potential is None or self.potential_optimizer is None:
            return {}
        demos = sample(self.demos, self.config.batch_size, self.q.device)
        to_go = demos.get("to_go", None)
        if to_go is None:
            return {}
        loss = potential_loss(self.potential, demos["observation"], to_go, self.config.gamma)
        if loss is None:
            return {}
        norm = self.clip_step(loss, self.potential.parameters(), self.potential_optimizer)
        return {"losses/potential_fit": float(loss.detach()), "losses/potential_grad_norm": norm}

    def reward_step(self) -> dict[str, float]:
        """One reward-network update: regression of ``R(s, a)`` on the Q-function's implicit reward
        ``Q(s, a) - gamma V(s')`` over a mixed batch."""
        cfg = self.config
        batch, _ = self.mixed_batch(offline=False)
        obs, actions = batch["observation"], batch["action"].long().reshape(-1)
        with torch.no_grad():
            q_taken = self.q.network(obs).gather(1, actions[:, None]).squeeze(1)
            next_value = soft_value(self.target_q(batch[("next", "observation")]), cfg.alpha)
            terminated = batch[("next", "terminated")].reshape(-1)
            next_obs = batch[("next", "observation")]
            at_goal = goal_reached(next_obs, self.reward.n_beams, self.goal_tolerance, self.max_range)
            next_value, terminated = absorbing_next(cfg, next_value, terminated, at_goal)
            target = implicit_reward(q_taken, next_value, terminated, cfg.gamma)
        predicted = self.reward(obs).gather(1, actions[:, None]).squeeze(1)
        loss = torch.nn.functional.mse_loss(predicted, target)
        norm = self.clip_step(loss, self.reward.parameters(), self.reward_optimizer)
        return {"losses/reward_fit": float(loss.detach()), "losses/reward_grad_norm": norm}

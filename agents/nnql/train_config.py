"""`navlearn train --local`'s settings besides NNQLConfig: the run and what its robots observe.

Apart from agents.nnql.train_local (torch, the world) so the command line builds fast; the flags of
`train` are these fields' (services.common.options), spelled as `up`'s and `nirl train`'s.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from worlds.config import OBSERVATIONS, SUBGOALS, TRAINING_DISCS, TRAINING_MAPS, NavConfig, observation_field


@dataclass
class LocalTrainConfig:
    """Budget, environment and outputs of one local training run."""

    steps: int = 200_000
    """robot-steps (transitions) to collect, summed over the vector env"""
    envs: int = 16
    """robots stepped together in the vector env"""
    maps: str = TRAINING_MAPS
    """training map spec (worlds.tasks.parse_map_spec): mixed:16-64 (the default: a side per map from 16
    to 64 cells), mixed:16, mixed:16,mixed:32, or map files (a
    map_server .yaml, a MovingAI .map/.scen, an ASCII map, a directory) with key=value options such as
    min_distance=5,unknown=free (docs/maps.md); the cell size chosen is printed"""
    moving_discs: int = TRAINING_DISCS
    """each training episode has 0..moving_discs moving discs, uniform (0: none; the dynamic set has 4)"""
    seed: int = 0
    """seeds the env, the learner and the exploration"""
    out: str = "runs/nnql-local"
    """output directory: policy (model.safetensors + config.json), curve.png, curve.jsonl, summary.json"""
    eval_every: int = 25_000
    """robot-steps between greedy evaluations on held-out maps (0: only the final one)"""
    eval_episodes: int = 100
    """episodes of each periodic evaluation per map size (validation set, seed 1)"""
    eval_sizes: tuple[int, ...] = (16, 32, 48, 64)
    """map sides (cells) of the periodic and final evaluations: keep_best scores the mean success over
    them, so the policy kept is the one that holds at every size (the first is the set named "unseen",
    the others "unseen@N")"""
    eval_dynamic_episodes: int = 0
    """episodes with 4 moving discs added to each periodic evaluation (the validation seed's dynamic set);
    keep_best then scores the success pooled over both sets (0: unseen static maps only)"""
    keep_best: bool = True
    """save the weights that scored best on the validation evaluations (seed 1) rather than the last"""
    final_eval_episodes: int = 100
    """episodes of the final evaluation (test set, seed 0: generated maps never trained on)"""
    progress: bool = True
    """show a progress bar"""
    device: str = "cpu"
    """where the learner's networks, loss and sampled batches live: cpu, cuda (cuda:N) or auto (a GPU if
    torch has one; agents.device)"""


@dataclass
class TrainObservation:
    """What the robots of a local run observe: a named observation and options on top of it."""

    observation: str = observation_field()
    """the named observation (worlds.config.OBSERVATIONS): learning (24 sector minima, goal, own-map
    subgoal), learning_plan (and the own map's plan length to the goal) or plain (8 beams + goal)"""
    patch_size: int = 0
    """add an egocentric PATCH x PATCH patch of the robot's own map (occupancy + visits), read by a small
    CNN beside the MLP (NNQLConfig.network patch, shaped by NNQLConfig.patch); 0: none"""
    subgoal: str = field(default="", metadata={"choices": SUBGOALS, "shown": "the named observation's"})
    """the subgoal planned on the robot's own map (own_map: learning's), on the true map (known_map) or
    none (learning alone, e.g. with a patch)"""
    frame_stack: int = 1
    """observe the last K frames, newest first (1: one frame)"""
    previous_action: bool = False
    """observe the previous action, one-hot"""
    range_rate: bool = False
    """observe each reading's change since the previous step (a motion cue for moving discs)"""
    plan_length: bool = False
    """observe the length of the subgoal's path to the goal on the robot's own map (how far the goal is
    round the walls seen so far); needs the subgoal"""

    def nav(self) -> NavConfig:
        """The named observation's task with these options applied (ValueError for a bad combination)."""
        named = OBSERVATIONS[self.observation]
        observation = replace(
            named.observation,
            patch_size=self.patch_size,
            subgoal=self.subgoal or named.observation.subgoal,
            frame_stack=self.frame_stack,
            previous_action=self.previous_action or named.observation.previous_action,
            range_rate=self.range_rate or named.observation.range_rate,
            plan_length=self.plan_length or named.observation.plan_length,
        )
        return replace(named, observation=observation)

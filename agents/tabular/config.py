"""The tabular learners' settings, apart from their numba kernels so the command line reads them
without compiling anything (`navlearn tabular`'s flags are these fields)."""

from __future__ import annotations

from dataclasses import dataclass, field

EXPLORATIONS = ("epsilon-greedy", "boltzmann")
ALPHA_SCHEDULES = ("constant", "visits")


@dataclass(frozen=True)
class StepSizeConfig:
    """What every tabular learner takes: episodes, discount, step-size schedule and seed (TD(0)
    prediction's whole config; control adds its exploration)."""

    episodes: int = 20000
    """Number of episodes."""
    gamma: float = 0.95
    """Discount factor."""
    alpha: float = 0.5
    """Step size (its first value under the "visits" schedule)."""
    alpha_schedule: str = field(default="visits", metadata={"choices": ALPHA_SCHEDULES})
    """"constant", or "visits": alpha / n ** alpha_power after n visits of the state (-action pair)."""
    alpha_power: float = 0.6
    """Exponent of the "visits" schedule, in (0.5, 1] for convergence (1 = sample average)."""
    seed: int = 0
    """Seed of the learner's random generator."""

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise ValueError(f"episodes must be >= 1, got {self.episodes}")
        if not 0.0 <= self.gamma <= 1.0:
            raise ValueError(f"gamma must be in [0, 1], got {self.gamma}")
        if not 0.0 < self.alpha <= 1.0:
            raise ValueError(f"alpha must be in (0, 1], got {self.alpha}")
        if self.alpha_schedule not in ALPHA_SCHEDULES:
            raise ValueError(f"alpha_schedule must be one of {ALPHA_SCHEDULES}, got {self.alpha_schedule!r}")
        if not 0.0 < self.alpha_power <= 1.0:
            raise ValueError(f"alpha_power must be in (0, 1], got {self.alpha_power}")


@dataclass(frozen=True)
class TabularConfig(StepSizeConfig):
    """Control by SARSA, Q-learning or Monte Carlo: the step sizes and the exploration."""

    exploration: str = field(default="epsilon-greedy", metadata={"choices": EXPLORATIONS})
    """"epsilon-greedy" (random action with probability epsilon) or "boltzmann" (softmax of Q/temperature)."""
    explore_start: float = 1.0
    """Epsilon, or temperature, in the first episode."""
    explore_end: float = 0.01
    """Epsilon, or temperature, at the end of the decay and after it."""
    explore_decay: float = 0.7
    """Fraction of the episodes over which exploration decays geometrically from start to end."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.exploration not in EXPLORATIONS:
            raise ValueError(f"exploration must be one of {EXPLORATIONS}, got {self.exploration!r}")
        if not (self.explore_start > 0 and self.explore_end > 0):
            raise ValueError("explore_start and explore_end must be positive")
        if self.exploration == "epsilon-greedy" and max(self.explore_start, self.explore_end) > 1:
            raise ValueError("epsilon (explore_start, explore_end) must be in (0, 1]")
        if not 0.0 <= self.explore_decay <= 1.0:
            raise ValueError(f"explore_decay must be in [0, 1], got {self.explore_decay}")


@dataclass(frozen=True)
class TDConfig(StepSizeConfig):
    """TD(0) prediction: the step sizes every tabular learner takes (a visit counts states here)."""


@dataclass(frozen=True)
class MonteCarloConfig(TabularConfig):
    """Monte Carlo control; the fields of TabularConfig plus the visit rule."""

    first_visit: bool = True
    """Update from the first visit of (s, a) in an episode only (False: every visit)."""

"""The learner's update-to-data rate limiter (Reverb's ``SampleToInsertRatio``, counted in updates).

Reverb keeps ``diff = samples_per_insert * inserts - samples`` inside a band
``[min_diff, max_diff]`` around ``samples_per_insert * min_size_to_sample`` of
width ``2 * error_buffer``: sampling waits while it would leave the band below
(the learner would train on a trickle), inserting waits while the band is
exceeded above (the learner would drown in data it never trains on). Here a
"sample" is one gradient update of a whole batch, so the ratio is the NNQL
update-to-data ratio (updates per inserted transition). The learner stops
draining its inbox while inserts are blocked; actors wait for the learner's
acknowledgements, so the back-pressure reaches them as it does in Reverb.

Pure bookkeeping, no clocks and no threads: the learner's main loop asks
:meth:`can_update` / :meth:`can_insert` and reports with :meth:`inserted` /
:meth:`updated`.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class RateLimiter:
    """Bounded update-to-data ratio with a minimum replay size before the first update."""

    updates_per_insert: float
    """target gradient updates per inserted transition (e.g. 0.125: one update per 8 transitions)"""
    min_size: int
    """transitions in replay before the first update"""
    tolerance: float
    """how far (in updates) the learner may run ahead of or behind the target ratio; >= 1"""
    inserts: int = 0
    """transitions inserted so far"""
    updates: int = 0
    """updates run so far"""

    def __post_init__(self) -> None:
        if self.updates_per_insert <= 0:
            raise ValueError(f"updates_per_insert must be > 0, got {self.updates_per_insert}")
        if self.min_size < 1:
            raise ValueError(f"min_size must be >= 1, got {self.min_size}")
        if self.tolerance < 1:
            raise ValueError(
                f"tolerance must be >= 1 update (or nothing could ever run), got {self.tolerance}"
            )

    @property
    def diff(self) -> float:
        """Updates owed: the ratio times the inserts, minus the updates already run."""
        return self.updates_per_insert * self.inserts - self.updates

    @property
    def min_diff(self) -> float:
        return self.updates_per_insert * self.min_size - self.tolerance

    @property
    def max_diff(self) -> float:
        return self.updates_per_insert * self.min_size + self.tolerance

    def can_update(self, replay_size: int) -> bool:
        """One more update keeps the ratio in its band and the replay holds ``min_size`` transitions."""
        return replay_size >= self.min_size and self.diff - 1 >= self.min_diff

    def updates_allowed(self, replay_size: int) -> int:
        """How many updates may run now, back to back."""
        if replay_size < self.min_size:
            return 0
        return max(int(self.diff - self.min_diff), 0)

    def can_insert(self) -> bool:
        """Inserts are open until the learner is ``tolerance`` updates behind the ratio.

        Checked before a whole batch goes in, so ``diff`` may overshoot ``max_diff`` by one
        batch; what matters is that the overshoot is bounded.
        """
        return self.diff <= self.max_diff

    def inserted(self, count: int) -> None:
        self.inserts += int(count)

    def updated(self, count: int = 1) -> None:
        self.updates += int(count)

    def state(self) -> dict[str, int]:
        """Counters to checkpoint (the ratio and band come from the configuration)."""
        return {"inserts": self.inserts, "updates": self.updates}

    def load_state(self, state: dict[str, int]) -> None:
        self.inserts = int(state["inserts"])
        self.updates = int(state["updates"])

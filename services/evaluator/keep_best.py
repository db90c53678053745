"""The evaluator's keep-best: the best-evaluated version's weights, saved as a policy directory.

The learner's greedy policy swings from version to version, so a run's last weights are often not its
best. The evaluator holds the very weights it measured, so it keeps them: each time a version scores at
least as well as the best so far (agents.evaluation.selection.score; ties go to the later version) its
weights are written to ``--best-policy`` (atomically: a crash leaves the old or the new one), with the
version, the figures and the seed that chose it under ``kept`` in its config.json. `navlearn up` makes
that directory the run's policy. A restarted evaluator reads the kept score back, so a resumed run
competes with its earlier versions.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import Any

from agents.evaluation.selection import score
from agents.mlp import CONFIG_FILE
from agents.nnql.persistence import replace_dir
from agents.nnql.policy import save_policy_dir
from protocols.messages import WeightsUpdate

log = logging.getLogger("navlearn.evaluator")
KEPT = "kept"
"""the key of a kept policy's config.json that says why it was kept"""


def kept_record(path: str | Path) -> dict[str, Any] | None:
    """The ``kept`` record of the policy directory ``path`` (None when there is no kept policy)."""
    config = Path(path) / CONFIG_FILE
    if not config.is_file():
        return None
    return json.loads(config.read_text()).get(KEPT)


class KeepBest:
    """Saves the weights of each evaluated version that scores at least the best so far."""

    def __init__(self, path: str | Path, eval_seed: int, env: dict[str, Any] | None = None) -> None:
        """``env``: the env record the saved policy carries (worlds.own_env.EnvConfig.record; None:
        navlearn's world), so `navlearn evaluate --policy` rebuilds it."""
        self.path = Path(path)
        self.eval_seed = eval_seed
        self.env = env
        earlier = kept_record(self.path)
        self.best: tuple[float, float] | None = tuple(earlier["score"]) if earlier else None
        self.version: int | None = earlier["version"] if earlier else None

    def offer(self, message: WeightsUpdate, metrics: dict[str, Any]) -> bool:
        """Keep ``message``'s weights if their ``metrics`` score at least the best so far."""
        figure = score(metrics)
        if self.best is not None and figure < self.best:
            return False
        record = {
            "version": message.version,
            "score": list(figure),
            "eval_seed": self.eval_seed,
            "learner": message.sender,
            "time": time.time(),
            "metrics": metrics,
        }
        metadata: dict[str, Any] = {KEPT: record}
        if message.observation is not None:
            metadata["observation"] = message.observation
        if self.env is not None:
            metadata["env"] = self.env
        replace_dir(
            self.path,
            lambda tmp: save_policy_dir(
                tmp, message.tensors, message.architecture, message.version, **metadata
            ),
        )
        if self.version is not None:
            log.info("version %d scores %s, kept over version %d", message.version, figure, self.version)
        self.best, self.version = figure, message.version
        return True

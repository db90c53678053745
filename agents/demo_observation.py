"""What a demonstration dataset observes, and the check that a learner observes the same.

A dataset records the observation settings its robot had (``worlds.config.observation_settings``,
in the ``navlearn`` JSON of its metadata, written by ``agents.demos.write_demos``). With the
own-map subgoal (``worlds.config.LEARNING_NAV``) the observation depends on the trajectory the
robot drove, so a demonstration cannot be converted to another observation: it is recorded in
the one its learner uses (``navlearn demos generate --observation``), and a learner of another
observation refuses it with one error naming the file and every differing field. Sets written
before the record observe ``worlds.config.LEGACY_OBSERVATION`` (8 beams + goal) when their width
is that one's; they still load, in that observation (``--observation plain``).
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from agents.demos import Demo, DemoFormatError, dataset_location, datasets_root, load_demos
from worlds.config import (
    LEARNING_NAV,
    LEGACY_OBSERVATION,
    OBSERVATIONS,
    NavConfig,
    observation_differences,
    observation_name,
    observation_settings,
)
from worlds.perception import frame_dim, frame_layout, observation_dim


def recorded_observation(navlearn_metadata: str | dict | None, width: int) -> dict | None:
    """The observation settings of a dataset from its ``navlearn`` metadata (JSON text or decoded)
    and observation width; legacy for an unrecorded set of the legacy width; None if unknown."""
    meta = navlearn_metadata or {}
    if isinstance(meta, str):
        try:
            meta = json.loads(meta)
        except ValueError:
            meta = {}
    recorded = meta.get("observation") if isinstance(meta, dict) else None
    if recorded is None and width == observation_dim(OBSERVATIONS["plain"]):
        return dict(LEGACY_OBSERVATION)
    return None if recorded is None else dict(recorded)


def dataset_observation(path: str | Path) -> tuple[dict | None, int]:
    """``(observation settings or None, values per step)`` of the dataset at ``path``."""
    import minari

    root, dataset_id = dataset_location(path)
    if not (root / dataset_id / "data").is_dir():
        raise DemoFormatError(f"{root / dataset_id}: no such demonstration dataset")
    try:
        with datasets_root(root):
            dataset = minari.load_dataset(dataset_id)
        width = int(dataset.observation_space.shape[0])
        navlearn = dataset.storage.metadata.get("navlearn")
    except Exception as exc:  # damaged files: load_demos gives the same one-line error
        raise DemoFormatError(
            f"{root / dataset_id}: unreadable demonstration dataset ({type(exc).__name__}: {exc})"
        ) from None
    return recorded_observation(navlearn, width), width


def check_observation(where: str | Path, recorded: dict | None, width: int, nav: NavConfig) -> None:
    """A DemoFormatError naming ``where`` and every differing field unless demonstrations of
    ``width`` values per step, recorded in the ``recorded`` settings, are what ``nav`` observes."""
    want = observation_dim(nav)
    if recorded is None:  # nothing recorded: the width is all there is to check
        if width != want:
            raise DemoFormatError(
                f"{where}: observations have {width} values per step, the learner's have {want}; "
                "record the demonstrations in the learner's observation"
            )
        return
    wrong = observation_differences(recorded, nav, other="the learner")
    if wrong:
        theirs, learners = observation_name(recorded), observation_name(observation_settings(nav))
        train = (
            f"train in their observation (--observation {theirs})" if theirs else "train in their observation"
        )
        again = f" (navlearn demos generate --observation {learners})" if learners else ""
        raise DemoFormatError(
            f"{where}: the demonstrations were recorded observing " + ", ".join(wrong) + f"; {train} or "
            f"record them again in the learner's{again}"
        )


def plan_length_columns(recorded: dict | None, nav: NavConfig) -> np.ndarray | None:
    """The columns to keep of a set ``recorded`` observing the plan length for a learner in ``nav``,
    which observes the same without it (None when that is not the case: nothing to convert)."""
    if recorded is None or not recorded.get("observation.plan_length") or nav.observation.plan_length:
        return None
    with_plan = replace(nav, observation=replace(nav.observation, plan_length=True))
    if observation_differences(recorded, with_plan):
        return None
    start, stop = frame_layout(with_plan)["plan_length"]
    width = frame_dim(with_plan)
    keep = np.ones(observation_dim(with_plan), bool)
    for frame in range(nav.observation.frame_stack):
        keep[frame * width + start : frame * width + stop] = False
    return np.flatnonzero(keep)


def load_demos_for(path: str | Path, nav: NavConfig = LEARNING_NAV) -> list[Demo]:
    """The demonstrations at ``path``, checked to observe what a learner in ``nav`` observes
    (default :data:`worlds.config.LEARNING_NAV`); a set recorded with the plan length, for a
    learner without it, loads with that column dropped (exact; the module docstring says why)."""
    demos = load_demos(path)  # its own one-line errors for missing or damaged sets come first
    root, dataset_id = dataset_location(path)
    recorded, width = dataset_observation(path)
    keep = plan_length_columns(recorded, nav)
    if keep is not None and width == len(keep) + nav.observation.frame_stack:
        return [replace(d, observations=np.ascontiguousarray(d.observations[:, keep])) for d in demos]
    check_observation(root / dataset_id, recorded, width, nav)
    return demos

"""Screening helpers of ``bench/nirl.py`` (issue 15 part 3): where validation-seed runs go (NIRLConfig
overrides from the command line: ``bench._common.parse_overrides``), held-out expert episodes for
``--diagnose`` and a pickle cache of generated demonstrations (``--demo-cache``)."""

from __future__ import annotations

import argparse
import pickle
from pathlib import Path

import numpy as np
import torch

from agents.nirl.config import NIRLRun
from agents.planning.demonstrate import generate_demos
from worlds.config import NavConfig

VALIDATION_RUNS = "runs/nirl_validation.jsonl"
"""screening runs (``--split validation``): never mixed with the test seed's table"""


def heldout_demos(seed: int, nav: NavConfig) -> list:
    """20 clean expert episodes on maps no demonstration set uses (the reward off the demonstrations)."""
    return generate_demos("mixed:16", 20, seed=30_000 + seed, config=nav)[0]


def cached(directory: str | None, name: str, make, *args):
    """``make(*args)``, pickled under ``directory`` (None: no cache) so repeated screening runs skip the
    expert's planning; the demonstrations depend only on the name's seed, noise and observation."""
    if not directory:
        return make(*args)
    path = Path(directory) / f"{name}.pkl"
    if path.exists():
        return pickle.loads(path.read_bytes())
    value = make(*args)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(pickle.dumps(value))
    return value


POLICY_RUNS = "runs/nirl_out"
"""where bench runs with ``policy_steps`` or ``--save-runs`` save NIRL's files: <split>-<set>-<seed>
(results/nirl/scripts/nirl_refine.py)"""


def add_policy_options(parser: argparse.ArgumentParser) -> None:
    """Options of NIRL's NNQL phase (``--nirl policy_steps=N``, agents.nirl.policy_iteration) and of its
    own rounds' experience (``--nirl-discs``)."""
    parser.add_argument(
        "--nirl-discs",
        type=int,
        default=NIRLRun().moving_discs,
        help="0..N moving discs per episode of NIRL's own rounds (NIRLRun.moving_discs; default "
        f"{NIRLRun().moving_discs}, `navlearn nirl train`'s; 0: static maps, the rows recorded before issue "
        "15 part 9 and the runs that omitted the flag until 2026-12-07, whose lines carry no nirl_discs)",
    )
    parser.add_argument("--policy-eval-every", type=int, default=25_000,
                        help="NIRL with policy_steps: robot-steps between keep-best validations")  # fmt: skip
    parser.add_argument("--policy-eval-dynamic", type=int, default=100,
                        help="... and validation episodes with 4 moving discs beside")  # fmt: skip
    parser.add_argument("--save-runs", action="store_true",
                        help=f"save every NIRL run's files (policy, reward, potential) to {POLICY_RUNS}/"
                        "<split>-<set>-<seed>, as runs with policy_steps always do (results/nirl/scripts/"
                        "nirl_refine.py reads them)")  # fmt: skip


def policy_run(args: argparse.Namespace, set_name: str, seed: int) -> dict:
    """NIRLRun fields of the NNQL phase from the bench's options (no files without ``policy_steps`` or
    ``--save-runs``)."""
    save = args.save_runs or args.nirl_overrides.get("policy_steps")
    saved = f"{POLICY_RUNS}/{args.split}-{set_name}-{seed}" if save else ""
    return {"out": saved, "policy_eval_every": args.policy_eval_every, "eval_episodes": args.val_episodes,
            "policy_eval_dynamic_episodes": args.policy_eval_dynamic,
            "moving_discs": args.nirl_discs}  # fmt: skip


def policy_phase(result, curve: list, expert_labels: list | None) -> dict:
    """The NNQL phase of a NIRL run in the bench's terms: its kept policy, robot-steps (IQ-Learn's
    rounds included), the validation points along it appended to ``curve`` at NIRL's
    robot-steps, what keep-best chose, and with the noisy set's ``expert_labels`` the rates of the
    MAP refinement after it (agents.nirl.refine_progress)."""
    phase = result.policy_result
    extra = {}
    if expert_labels is not None and result.refinement is not None:
        steps = result.learner.demos.storage.get(torch.arange(len(result.learner.demos)))
        extra["map_refinement_progress"] = rates(steps["action"], result.refinement.labels,
                                                 np.concatenate(expert_labels))  # fmt: skip
    curve.extend((p["env_steps"], p["eval_success"], p.get("eval_dynamic_success"))
                 for p in result.curve if p.get("phase") and "eval_success" in p)  # fmt: skip
    extra |= {"selected_version": phase.selected_version, "policy_wall": round(phase.wall_time, 1)}
    extra |= {"iq_steps": int(result.iq_steps), "steps": int(result.env_steps)}
    return {"policy": result.policy(), **extra}


def rates(recorded, labels, expert) -> dict:
    """Injected steps (recorded != expert) relabelled to the expert's action, and clean steps kept."""
    recorded, labels, expert = (torch.as_tensor(np.asarray(x)).long() for x in (recorded, labels, expert))
    wrong = recorded != expert
    return {
        "injected_steps": int(wrong.sum()),
        "clean_steps": int((~wrong).sum()),
        "injected_relabelled_to_expert": float((labels[wrong] == expert[wrong]).float().mean()),
        "injected_changed": float((labels[wrong] != recorded[wrong]).float().mean()),
        "clean_kept": float((labels[~wrong] == recorded[~wrong]).float().mean()),
    }

"""NIRL benchmark (issue 15): NIRL (IQ-Learn core) against every baseline on the same demonstrations
and the same test episodes, and NIRL's robot-steps against NNQL from scratch.

Demonstrations: the modified-A* expert on training maps (``mixed:16``), per seed s one clean set
(seed 10000 + s; the first 5, 10 and 20 episodes) and one noisy set of 20 (seed 20000 + s; each
action, with probability 0.3, a random wall-free one; learners see the recorded actions only).
Learners, each per (demo set, seed):

* ``bc``    behaviour cloning (agents.imitation) trained properly: minibatches of 32 (many steps
            per epoch), early stopping with patience 30 on a validation split of whole episodes;
* ``sqil``  SQIL (Reddy et al. 2020) on NNQL's Q-network: soft Q-learning, reward 1 on demonstrated
            steps and 0 on own, 50/50 batches (``NIRLConfig(core="sqil")``), NIRL's env budget;
* ``dqfd``  NNQL with the demonstrations in replay, DQfD-style (Hester et al. 2018): the environment's
            reward, demonstrations kept in their own buffer and 25% of each batch, DQfD's large-margin
            loss (0.8) on them, 500 pre-training updates on demonstrations alone; NIRL's env budget;
            the disc mix and head of ``nnql`` (``--nnql-discs``, ``--nnql-dueling``);
* ``nirl``  NIRL with its default core (IQ-Learn), ``--iterations`` x ``--steps-per-iteration``;
* ``maxmargin`` the max-margin core with issue 8's settings (gamma 0.95 ...), the same budget;
* ``nnql``  NNQL from scratch (``train --local`` defaults), ``--nnql-steps``: once per seed, no demos.
* ``nnql_line`` the same on the straight-line progress reward (``RewardConfig()``: progress 0.1 per metre,
            no geodesic term) - the reward a user without the map can write, where ``nnql``'s geodesic
            progress reads the true map's shortest paths (a training signal NIRL does not have).

Every policy is evaluated greedily on the same ``--episodes`` test episodes per family (seed 0:
"unseen" static generated maps and "dynamic", the same with 4 moving discs): success with its
Wilson 95% interval, per-episode outcomes kept so McNemar's exact test compares NIRL with behaviour
cloning on the same episodes. Learning time: NIRL (20 clean demos) and NNQL from scratch are
validated on 50 validation-seed episodes along the way; robot-steps to a fixed validation success.
The grid-world check (``agents.nirl.gridcheck``) measures reward recovery where the true reward is known.

Observation (``--nav``): ``learning`` (the default, ``worlds.config.LEARNING_NAV``: 24 sector minima,
the goal, the subgoal from the robot's own map, geodesic progress reward for the learners that use the
environment's reward), ``learning_plan`` (the same and the length of the own map's plan to the
goal, ``ObservationConfig.plan_length``) or ``default`` (``NavConfig()``: 8 beams + goal, the first
table's). The expert acts on the true map either way; its demonstrations are recorded in the
chosen observation, and its own success on the same test episodes is measured beside (``--methods expert``).

Runs append one JSON line each to ``--runs`` (default ``results/nirl/nirl_runs_learning.jsonl`` for
``--nav learning``, ``results/nirl/nirl_runs.jsonl``, the first table's, for ``--nav default``; so the grid
can be run in pieces, in the background); each line records its observation. ``--report`` reads them
and prints the table (``bench/_nirl_report.py``), then one JSON object on the last line.

    python -m bench.nirl --methods nirl,bc --sets 20,20noisy --seeds 0,1,2    # a piece
    python -m bench.nirl --report                                             # the table
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch

from agents.evaluation import evaluate, make_eval_set
from agents.evaluation.metrics import wilson_interval
from agents.imitation.config import ImitationConfig
from agents.imitation.train import train_policy
from agents.nirl.buffers import demo_buffer, sample
from agents.nirl.config import NIRLConfig, NIRLRun
from agents.nirl.diagnose import demo_figures
from agents.nirl.learner import NIRLLearner
from agents.nirl.losses import max_margin_loss
from agents.nirl.max_margin import Q_KEYS
from agents.nirl.train_local import train_nirl
from agents.nnql.config import NNQLConfig
from agents.nnql.learner import NNQLLearner
from agents.nnql.ratelimit import RateLimiter
from agents.nnql.rollout import VectorRollout
from agents.nnql.train_local import LocalTrainConfig, train_local
from agents.nnql.transitions import transitions_to_tensordict
from agents.planning.demonstrate import generate_demos
from bench._common import machine_load, parse_overrides
from bench._nirl_options import (
    VALIDATION_RUNS,
    add_policy_options,
    cached,
    heldout_demos,
    policy_phase,
    policy_run,
    rates,
)
from bench._nirl_report import FAMILIES, METHODS, SETS, report
from bench.planning import expert_outcomes
from worlds.config import (
    LEARNING_NAV,
    LEARNING_PLAN_NAV,
    NavConfig,
    RewardConfig,
    observation_settings,
    with_moving_discs,
)
from worlds.outcomes import Outcome
from worlds.perception import observation_dim

ISSUE8 = {
    "core": "max_margin", "gamma": 0.95, "target_tau": 0.005, "prior_temperature": 0.1,
    "relabel_threshold": 0.6, "demo_noise": 0.2, "refine_start": 0, "demo_fraction": 0.25,
    "temperature_start": 0.3, "temperature_end": 0.02, "q_updates": 256,
}  # fmt: skip
"""NIRLConfig of the max-margin learner as issue 8 measured it (its defaults then)"""
SQIL = {"core": "sqil", "q_updates": 256}
"""SQIL as the tables measured it (256 Q updates per round, NIRL's default before issue 15 part 3)"""
VALIDATION_SEED = 1
NAVS = {
    "learning": LEARNING_NAV,
    "learning_plan": LEARNING_PLAN_NAV,
    "default": NavConfig(),
}
NO_DEMOS = ("nnql", "nnql_line")
"""learners that take no demonstrations (one run per seed)"""
RUNS = {
    "learning": "results/nirl/nirl_runs_learning.jsonl",
    "learning_plan": "results/nirl/nirl_runs_learning_plan.jsonl",
    "default": "results/nirl/nirl_runs.jsonl",
}


def demo_sets(
    seed: int, noise: float, nav: NavConfig, larger: int = 0
) -> tuple[dict[str, list], list[np.ndarray]]:
    """The clean (first 5, 10, 20 episodes) and noisy sets of ``seed``; with ``larger`` > 20 also the
    clean set continued to that many episodes (set ``str(larger)``; failures dropped as always)."""
    clean, _ = generate_demos("mixed:16", 20, seed=10_000 + seed, config=nav)
    noisy, _ = generate_demos("mixed:16", 20, seed=20_000 + seed, noise=noise, config=nav)
    expert_labels = [d.labels.copy() for d in noisy]
    for demo in noisy:  # the learners see the recorded actions only
        demo.expert_actions = None
    sets = {"5": clean[:5], "10": clean[:10], "20": clean, "20noisy": noisy}
    if larger > 20:  # episodes 20 .. larger - 1 of the same sequence (episode i resets with seed + i)
        more, _ = generate_demos("mixed:16", larger - 20, seed=10_000 + seed + 20, config=nav)
        sets[str(larger)] = clean + more
    return sets, expert_labels


def outcomes_of(result, family: str) -> list[int]:
    return [int(e.outcome == 1) for e in result.episodes[family]]


def figures(result) -> dict:
    out = {}
    for family in FAMILIES:
        m = result.metrics[family]
        out[family] = {
            "success": m.success.value,
            "success_ci": [m.success.low, m.success.high],
            "collision_static": m.collision_static.value,
            "collision_dynamic": m.collision_dynamic.value,
            "timeout": m.timeout.value,
            "path_ratio": None if m.path_ratio is None else float(m.path_ratio),
            "solved": outcomes_of(result, family),
        }
    return out


def expert_figures(sets, nav: NavConfig) -> dict:
    """The expert's own success on the same test episodes (it plans on the true map)."""
    out = {}
    for es in sets:
        outcomes = expert_outcomes(es, nav)
        solved = [int(o == Outcome.GOAL) for o in outcomes]
        low, high = wilson_interval(sum(solved), len(solved))
        static = float(np.mean([o == Outcome.COLLISION_STATIC for o in outcomes]))
        out[es.family] = {"success": float(np.mean(solved)), "success_ci": [low, high], "solved": solved,
                          "collision_static": static}  # fmt: skip
    return out


def validation_success(policy, episodes: int, nav) -> float:
    report = evaluate(policy, make_eval_set("unseen", episodes, seed=VALIDATION_SEED), nav)
    return report.metrics["unseen"].success.value


def train_dqfd(demos, seed: int, env_steps: int, nav: NavConfig, margin: float = 0.8, dueling: bool = False):
    """NNQL with demonstrations in replay, DQfD-style (see the module docstring); trains in ``nav`` as
    given (its moving discs included); ``dueling`` False: the plain head of the rows before part 13."""
    from worlds.vector_env import NavigationVectorEnv

    cfg = NNQLConfig(seed=seed, learning_starts=256, dueling=dueling, network="mlp")  # as the recorded rows
    obs_dim, n_actions = observation_dim(nav), nav.robot.n_actions
    q = NNQLLearner(cfg, obs_dim, n_actions, observation=observation_settings(nav))
    store = demo_buffer(50_000, seed + 1)
    for d in demos:
        store.extend(
            transitions_to_tensordict(
                {"obs": d.observations[:-1], "action": d.actions, "reward": d.rewards,
                 "next_obs": d.observations[1:], "terminated": d.terminations, "truncated": d.truncations},
                obs_dim,
            )
        )  # fmt: skip
    margins = torch.full((n_actions, n_actions), margin).fill_diagonal_(0.0)
    n_demo = cfg.batch_size // 4

    def update(pretrain: bool) -> None:
        demo = sample(store, cfg.batch_size if pretrain else n_demo).select(*Q_KEYS)
        batch = (
            demo if pretrain else torch.cat([sample(q.replay, cfg.batch_size - n_demo).select(*Q_KEYS), demo])
        )
        loss = q.loss(batch)["loss"]
        loss = loss + max_margin_loss(q.network(demo["observation"]), demo["action"], margins)
        q.optimizer.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(q.loss.parameters(), cfg.grad_clip)
        q.optimizer.step()
        q.target_updater.step()
        q.updates += 1

    for _ in range(500):
        update(pretrain=True)
    env = NavigationVectorEnv(16, config=nav, maps="mixed:16", seed=seed)
    policy = q.policy(seed=seed)
    policy.explore_as(cfg, q.version)
    rollout = VectorRollout(env, policy)
    rollout.reset(seed=seed)
    limiter = RateLimiter(cfg.utd_ratio, max(cfg.learning_starts, cfg.batch_size), tolerance=1.0)
    while rollout.steps < env_steps:
        batch, _ = rollout.step()
        limiter.inserted(q.add(batch))
        due = limiter.updates_allowed(len(q.replay))
        for _ in range(due):
            update(pretrain=False)
        limiter.updated(due)
        policy.set_weights(q.get_weights(), q.version)
        policy.explore_as(cfg, q.version)
    env.close()
    return q.policy(), rollout.steps


def run_one(
    method: str, set_name: str, seed: int, demos, expert_labels, args, sets, nav, heldout=None
) -> dict:
    t0 = time.perf_counter()
    row: dict = {"method": method, "set": set_name, "seed": seed, "episodes": args.episodes}
    if demos is not None:
        row["demo_episodes"] = len(demos)
        row["demo_steps"] = int(sum(len(d) for d in demos))
    budget = args.iterations * args.steps_per_iteration
    if method == "bc":
        config = ImitationConfig(seed=seed, batch_size=32, patience=30, max_epochs=400, val_fraction=0.25)
        trained = train_policy(
            demos, config, n_actions=nav.robot.n_actions, observation=observation_settings(nav)
        )
        policy, row["env_steps"] = trained.policy(), 0
        row["bc_epochs"], row["bc_best_epoch"] = len(trained.history), trained.best_epoch
        row["bc_steps_per_epoch"] = math.ceil(trained.train_steps / config.batch_size)
    elif method in ("nirl", "sqil", "maxmargin"):
        curve_run = method == "nirl" and (set_name == "20" or args.keep_best)  # keep-best validates anyway
        rounds = max(args.iterations, args.curve_iterations) if curve_run else args.iterations
        core = {"nirl": {"core": "iq"}, "sqil": SQIL, "maxmargin": ISSUE8}[method]
        overrides = args.nirl_overrides if method == "nirl" else {}
        config = NIRLConfig(
            **(core | overrides), iterations=rounds, steps_per_iteration=args.steps_per_iteration, seed=seed
        )
        curve, tested = [], {}

        def on_iteration(point, learner, curve=curve, tested=tested):
            if curve_run and learner.iteration % args.curve_every == 0:
                success = point.get("eval_success")  # keep-best's validation is the curve's
                if success is None:
                    success = validation_success(learner.policy(), args.val_episodes, nav)
                curve.append((point["env_steps"], success))
            if learner.iteration == args.iterations:
                tested["policy"], tested["steps"] = learner.policy(), int(point["env_steps"])
                tested["scale"] = {k: v for k, v in point.items() if k.startswith("nirl/")}
                if heldout and method != "maxmargin":  # the learned reward off the demonstrations
                    tested["diagnosis"] = {"train": demo_figures(learner, demos),
                                           "heldout": demo_figures(learner, heldout)}  # fmt: skip

        keep = {"keep_best": method == "nirl" and args.keep_best}  # NIRL's own rounds keep their best
        keep["eval_every"] = args.curve_every if keep["keep_best"] else 0
        # ... or average the last (not in a curve run longer than the tested rounds: its test is a snapshot)
        keep["average_last"] = args.average_last if method == "nirl" and rounds == args.iterations else 0.0
        run = NIRLRun(final_eval_episodes=0, progress=False, **keep, **policy_run(args, set_name, seed))
        row["nirl_discs"] = run.moving_discs
        result = train_nirl(demos, config, run, nav, on_iteration=on_iteration)
        if result.selected_iteration is not None or result.averaged_rounds:  # the kept round or the average
            tested["policy"], tested["steps"] = result.policy(), int(result.env_steps)
        if result.selected_iteration is not None:
            row["keep_best"], row["selected_iteration"] = True, result.selected_iteration
        elif result.averaged_rounds:
            row["averaged_rounds"] = result.averaged_rounds
        if config.policy_steps:  # the NNQL phase's policy is NIRL's (agents.nirl.policy_iteration)
            labels = expert_labels if "noisy" in set_name else None
            tested |= policy_phase(result, curve, labels)  # every set's phase curve (keep-best's points)
            row |= {k: v for k, v in tested.items() if k not in ("policy", "steps", "scale", "diagnosis")}
        policy, row["env_steps"] = tested["policy"], tested["steps"]
        row["reward_scale"] = tested.get("scale", {})
        if "diagnosis" in tested:
            row["diagnosis"] = tested["diagnosis"]
        if curve:
            row["curve"] = curve
        if set_name == "20noisy" and method != "sqil":
            row["map_refinement"] = refinement_rates(result.learner, expert_labels)
    elif method == "dqfd":
        trained_in = with_moving_discs(nav, args.nnql_discs)  # the same disc mix and head as ``nnql``
        policy, row["env_steps"] = train_dqfd(demos, seed, budget, trained_in, dueling=args.nnql_dueling)
        row["nnql_discs"], row["dueling"] = args.nnql_discs, args.nnql_dueling
    else:  # nnql from scratch: the env's reward (nnql) or the straight-line progress reward (nnql_line)
        reward_nav = nav if method == "nnql" else dataclasses.replace(nav, rewards=RewardConfig())
        result = train_local(
            LocalTrainConfig(steps=args.nnql_steps, eval_every=args.nnql_eval_every,
                             eval_episodes=args.val_episodes, keep_best=args.keep_best,
                             final_eval_episodes=0, out="", seed=seed, progress=False,
                             moving_discs=args.nnql_discs, maps="mixed:16", eval_sizes=(16,)),
            NNQLConfig(**{"seed": seed, "dueling": args.nnql_dueling, "network": "mlp",  # as recorded
                          **args.nnql_overrides}),
            nav=reward_nav,
        )  # fmt: skip
        kept = result.policy.greedy() if args.keep_best else result.learner.policy()  # the kept weights
        row["nnql_discs"] = args.nnql_discs
        policy, row["env_steps"] = kept, result.env_steps
        if args.keep_best:
            row["keep_best"], row["selected_version"] = True, result.selected_version
        row["curve"] = [(p["env_steps"], p["eval_success"]) for p in result.curve if "eval_success" in p]
    row["train_seconds"] = round(time.perf_counter() - t0, 1)
    row["test"] = figures(evaluate(policy, sets, nav))
    row["seconds"] = round(time.perf_counter() - t0, 1)
    return row


def refinement_rates(learner: NIRLLearner, expert_labels: list[np.ndarray]) -> dict:
    steps, refined = learner.refine_all()
    return rates(steps["action"], refined.labels, np.concatenate(expert_labels)[: len(steps)])


def code_version() -> str:
    """The commit the bench runs from, "+dirty" if the code has uncommitted changes (runs file aside)."""
    root = Path(__file__).resolve().parents[1]
    git = ["git", "-C", str(root)]
    commit = subprocess.run([*git, "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout
    runs = [f":!{path}" for path in RUNS.values()]
    tracked = [*git, "status", "--porcelain", "--untracked-files=no", "--", ".", *runs]
    dirty = subprocess.run(tracked, capture_output=True)
    return commit.strip() + ("+dirty" if dirty.stdout.strip() else "")


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--methods", default=",".join(METHODS), help="comma list of " + ", ".join(METHODS))
    parser.add_argument(
        "--sets",
        default=",".join(SETS),
        help="comma list of demo sets: " + ", ".join(SETS) + " or one larger clean set N > 20 (e.g. 500)",
    )
    parser.add_argument("--seeds", default="0,1,2", help="comma list of seeds")
    parser.add_argument("--episodes", type=int, default=500, help="test episodes per family")
    parser.add_argument("--iterations", type=int, default=10, help="NIRL/SQIL rounds (and DQfD's env budget)")
    parser.add_argument("--steps-per-iteration", type=int, default=2048, help="robot-steps per round")
    parser.add_argument(
        "--curve-iterations", type=int, default=30, help="NIRL rounds of the learning curve run"
    )
    parser.add_argument("--curve-every", type=int, default=3, help="NIRL rounds between validations")
    parser.add_argument("--nnql-steps", type=int, default=61_440, help="NNQL robot-steps from scratch")
    parser.add_argument("--nnql-eval-every", type=int, default=6_144, help="NNQL validation every N steps")
    parser.add_argument("--nnql-dueling", action="store_true",
                        help="NNQL from scratch (and dqfd) with its default dueling head (the recorded rows "
                        "before issue 15 part 7, and dqfd's before part 13: the plain head)")  # fmt: skip
    parser.add_argument("--nnql-discs", type=int, default=0,
                        help="NNQL from scratch (and dqfd) trains with 0..N moving discs per episode (train "
                        "--local's default: 6; the recorded rows before issue 15 part 9, and dqfd's before "
                        "part 13: 0, static maps)")  # fmt: skip
    parser.add_argument("--val-episodes", type=int, default=50, help="validation episodes of the curves")
    parser.add_argument("--noise", type=float, default=0.3, help="random-action probability of the noisy set")
    parser.add_argument(
        "--diagnose", action="store_true",
        help="NIRL/SQIL: also measure the learned reward on 20 held-out expert episodes (other maps)",
    )  # fmt: skip
    parser.add_argument(
        "--demo-cache", default=None, metavar="DIR",
        help="pickle the generated demonstrations in DIR and reuse them (screening)",
    )  # fmt: skip
    parser.add_argument("--gridcheck", action="store_true", help="also run the grid-world reward recovery")
    parser.add_argument(
        "--nav",
        choices=list(NAVS),
        default="learning",
        help="observation: LEARNING_NAV, LEARNING_NAV with the own map's plan length, or NavConfig()",
    )
    parser.add_argument("--runs", default=None, help="JSON lines file runs append to (default by --nav)")
    parser.add_argument(
        "--split", choices=("test", "validation"), default="test",
        help="episodes the policies are tested on: test seed 0 (the table) or the validation seed "
        f"{VALIDATION_SEED} (screening; runs then default to runs/nirl_validation.jsonl)",
    )  # fmt: skip
    parser.add_argument(
        "--nirl", action="append", default=[], metavar="KEY=VALUE",
        help="override a NIRLConfig field of the nirl learner (repeatable; JSON values: 1024, true, 0.5)",
    )  # fmt: skip
    parser.add_argument(
        "--nnql", action="append", default=[], metavar="KEY=VALUE",
        help="override an NNQLConfig field of NNQL from scratch (nnql, nnql_line; repeatable), e.g. "
        "network=local",
    )  # fmt: skip
    add_policy_options(parser)
    parser.add_argument(
        "--keep-best", action="store_true",
        help="nirl and nnql/nnql_line test the weights that scored best on their validations (every "
        "--curve-every rounds / --nnql-eval-every robot-steps, --val-episodes each, the last included) "
        "instead of the last; with --curve-iterations <= --iterations",
    )  # fmt: skip
    parser.add_argument(
        "--average-last", type=float, default=NIRLRun().average_last, metavar="FRACTION",
        help="nirl: the policy averages the Q-network's weights over this fraction of the rounds at the "
        "end (NIRLRun.average_last; 0: the last round's); not in a curve run longer than --iterations",
    )  # fmt: skip
    parser.add_argument("--report", action="store_true", help="print the table of --runs and stop")
    args = parser.parse_args()
    runs = Path(args.runs or (VALIDATION_RUNS if args.split == "validation" else RUNS[args.nav]))
    args.nirl_overrides = parse_overrides(parser, args.nirl, NIRLConfig, "--nirl")
    args.nnql_overrides = parse_overrides(parser, args.nnql, NNQLConfig, "--nnql")
    if args.keep_best and "nirl" in args.methods.split(",") and args.curve_iterations > args.iterations:
        parser.error("--keep-best keeps the best of the rounds tested: --curve-iterations <= --iterations")
    if args.report:
        return report(runs)
    nav = NAVS[args.nav]
    # which code, settings and observation made each line
    code = {"commit": code_version(), "argv": sys.argv[1:], "nav": args.nav, "split": args.split,
            "observation": observation_settings(nav), "nirl_overrides": args.nirl_overrides,
            **({"nnql_overrides": args.nnql_overrides} if args.nnql_overrides else {})}  # fmt: skip
    test_seed = VALIDATION_SEED if args.split == "validation" else 0
    sets = [make_eval_set(f, args.episodes, seed=test_seed) for f in FAMILIES]
    methods = [m for m in args.methods.split(",") if m]
    unknown = sorted(set(methods) - set(METHODS))
    if unknown:
        parser.error(f"unknown methods {unknown}")
    seeds = [int(s) for s in args.seeds.split(",")]
    for seed in seeds:
        if args.gridcheck:
            from agents.nirl.gridcheck import check_reward_recovery

            g = check_reward_recovery(gamma=0.99, seed=seed)
            row = {"method": "gridcheck", "set": "-", "seed": seed, **g.__dict__}
            with open(runs, "a") as fh:
                fh.write(json.dumps(row) + "\n")
            print(json.dumps(row), flush=True)
        if "expert" in methods and seed == seeds[0]:  # deterministic on the same episodes: once
            t0 = time.perf_counter()
            row = {"method": "expert", "set": "-", "seed": seed, "episodes": args.episodes,
                   "test": expert_figures(sets, nav), "env_steps": 0} | code  # fmt: skip
            row |= {"seconds": round(time.perf_counter() - t0, 1), "load": machine_load()}
            with open(runs, "a") as fh:
                fh.write(json.dumps(row) + "\n")
            short = {f: round(row["test"][f]["success"], 3) for f in FAMILIES}
            print(f"expert: {short}", flush=True)
        learners = [m for m in methods if m != "expert"]
        needs_demos = any(m not in NO_DEMOS for m in learners)
        larger = max([int(s) for s in args.sets.split(",") if s.isdigit()] + [0])
        demos, expert_labels = ({}, [])
        if needs_demos:
            name = f"sets-{args.nav}-{seed}-{args.noise}-{larger}"
            demos, expert_labels = cached(args.demo_cache, name, demo_sets, seed, args.noise, nav, larger)
        heldout = None
        if args.diagnose:
            heldout = cached(args.demo_cache, f"heldout-{args.nav}-{seed}", heldout_demos, seed, nav)
        for method in learners:
            for set_name in ["-"] if method in NO_DEMOS else [s for s in args.sets.split(",") if s]:
                row = run_one(method, set_name, seed, None if method in NO_DEMOS else demos[set_name],
                              expert_labels, args, sets, nav, heldout)  # fmt: skip
                row |= code | {"load": machine_load()}
                with open(runs, "a") as fh:
                    fh.write(json.dumps(row) + "\n")
                short = {f: round(row["test"][f]["success"], 3) for f in FAMILIES}
                print(f"{method} {set_name} seed {seed}: {short} in {row['seconds']} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

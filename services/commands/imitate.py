"""`navlearn imitate train`: a neural policy from demonstrations by back-propagation (thesis ch. 3)."""

from __future__ import annotations

import argparse

from agents.imitation.config import ImitationConfig
from services.common.options import OptionError, add_options, options_from_args
from worlds.config import OBSERVATIONS
from worlds.own_env import ENV_TITLE, EnvConfig


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "imitate",
        help="learn a navigation policy from demonstrations (behaviour cloning)",
        description="Policy learning from multiple demonstrations (thesis ch. 3).",
    )
    sub = parser.add_subparsers(dest="imitate_command", metavar="SUBCOMMAND", required=True)
    train = sub.add_parser(
        "train",
        help="train an MLP policy on a demonstration dataset",
        description="Train an MLP from observations to the expert's actions (cross-entropy, Adam) on a "
        "Minari demonstration dataset from `navlearn demos generate` (or `navlearn demos record --env` on "
        "your own Gymnasium env, given the same --env). Episodes are split into training "
        "and validation sets; training stops early when the validation loss stalls and keeps the best "
        "epoch. Writes model.safetensors + config.json (the shared policy format, loadable by "
        "`navlearn evaluate`) and training.jsonl (one line per epoch) into --out.",
    )
    train.add_argument(
        "--demos", required=True, help="demonstration dataset directory (e.g. demos/expert-v0)"
    )
    train.add_argument("--out", required=True, help="output policy directory")
    train.add_argument(
        "--observation",
        choices=list(OBSERVATIONS),
        help="what the robot observes: learning (worlds.config.LEARNING_NAV, NNQL's default), "
        "learning_plan (the same and the own map's plan length to the goal) or plain "
        "(8 beams + goal, older demonstration sets); the demonstrations must have been recorded in it, "
        "and the saved policy records it (default learning; not with --env)",
    )
    add_options(train, ImitationConfig, "NAVLEARN_IMITATE", "behaviour cloning")
    add_options(
        train, EnvConfig, "NAVLEARN_ENV", ENV_TITLE + "; the --demos of `navlearn demos record` on that env"
    )
    train.set_defaults(func=run_train)


def run_train(args: argparse.Namespace) -> int:
    import json
    import sys
    from pathlib import Path

    from rich.progress import Progress

    from agents.demo_observation import load_demos_for
    from agents.demos import DemoFormatError
    from agents.imitation.train import save_trained, train_policy
    from worlds.config import observation_settings

    try:
        config = options_from_args(ImitationConfig, args, "NAVLEARN_IMITATE")
        env = options_from_args(EnvConfig, args, "NAVLEARN_ENV")
        nav = OBSERVATIONS[args.observation or "learning"]
        if args.observation and not env.own_world:
            raise ValueError(
                f"--observation is navlearn's world's; with --env {env.env} the env's own is learnt"
            )
        if env.own_world:
            demos, n_actions, where = load_demos_for(args.demos, nav), nav.robot.n_actions, {}
            observation = observation_settings(nav)
        else:  # a user's Gymnasium env: demonstrations recorded on it (agents.env_demos), its spaces
            from agents.env_demos import load_env_demos
            from worlds.own_env import env_spaces

            demos, n_actions = load_env_demos(args.demos, env), env_spaces(env)[1]
            where, observation = {"env": env.record()}, None  # `navlearn evaluate --policy` rebuilds it
    except (OptionError, DemoFormatError, ValueError) as exc:
        print(f"navlearn imitate train: {exc}", file=sys.stderr)
        return 2
    if len(demos) < 2:
        print("navlearn imitate train: need at least 2 demonstrations", file=sys.stderr)
        return 2
    with Progress() as progress:
        bar = progress.add_task("epochs", total=config.max_epochs)

        def on_epoch(record: dict) -> None:
            progress.update(
                bar,
                advance=1,
                description=f"epoch {record['epoch']:3d} val loss {record['val_loss']:.3f} "
                f"acc {record['val_accuracy']:.3f}",
            )

        result = train_policy(demos, config, n_actions=n_actions, on_epoch=on_epoch, observation=observation)
    out = save_trained(args.out, result, config, demos=str(Path(args.demos).resolve()), **where)
    with open(out / "training.jsonl", "w") as fh:
        for record in result.history:
            fh.write(json.dumps(record) + "\n")
    best = result.best
    print(
        f"{len(demos)} demos ({result.train_steps} training / {result.val_steps} validation steps); "
        f"best epoch {result.best_epoch} of {len(result.history)}: val loss {best['val_loss']:.4f}, "
        f"val accuracy {best['val_accuracy']:.3f} -> {out}"
    )
    return 0

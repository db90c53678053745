"""`navlearn imitate train`: a neural policy from demonstrations by back-propagation (thesis ch. 3)."""

from __future__ import annotations

import argparse

from worlds.config import OBSERVATIONS


def _sizes(text: str) -> tuple[int, ...]:
    try:
        sizes = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated layer widths such as 128,128, got {text!r}"
        ) from None
    if not sizes or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"layer widths must be positive, got {text!r}")
    return sizes


def register(subparsers: argparse._SubParsersAction) -> None:
    from agents.imitation.config import ImitationConfig
    from agents.mlp import ACTIVATION_NAMES

    d = ImitationConfig()
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
        "Minari demonstration dataset from `navlearn demos generate`. Episodes are split into training "
        "and validation sets; training stops early when the validation loss stalls and keeps the best "
        "epoch. Writes model.safetensors + config.json (the shared policy format, loadable by "
        "`navlearn evaluate`) and training.jsonl (one line per epoch) into --out.",
    )
    train.add_argument(
        "--demos", required=True, help="demonstration dataset directory (e.g. demos/expert-v0)"
    )
    train.add_argument("--out", required=True, help="output policy directory")
    train.add_argument(
        "--hidden", type=_sizes, default=d.hidden_sizes, help="hidden layer widths, e.g. 128,128"
    )
    train.add_argument("--activation", choices=ACTIVATION_NAMES, default=d.activation, help="activation")
    train.add_argument("--lr", type=float, default=d.lr, help="Adam learning rate")
    train.add_argument("--batch-size", type=int, default=d.batch_size, help="minibatch size in steps")
    train.add_argument("--epochs", type=int, default=d.max_epochs, help="maximum number of epochs")
    train.add_argument(
        "--patience", type=int, default=d.patience, help="epochs without validation gain before stopping"
    )
    train.add_argument(
        "--val-fraction", type=float, default=d.val_fraction, help="share of episodes for validation"
    )
    train.add_argument(
        "--seed", type=int, default=d.seed, help="seed of the split, initial weights and batches"
    )
    train.add_argument(
        "--observation",
        choices=list(OBSERVATIONS),
        default="learning",
        help="what the robot observes: learning (worlds.config.LEARNING_NAV, NNQL's default), "
        "learning_plan (the same and the own map's plan length to the goal) or plain "
        "(8 beams + goal, older demonstration sets); the demonstrations must have been recorded in it, "
        "and the saved policy records it (default %(default)s)",
    )
    train.set_defaults(func=run_train)


def run_train(args: argparse.Namespace) -> int:
    import json
    import sys
    from pathlib import Path

    from rich.progress import Progress

    from agents.demo_observation import load_demos_for
    from agents.demos import DemoFormatError
    from agents.imitation.config import ImitationConfig
    from agents.imitation.train import save_trained, train_policy
    from worlds.config import observation_settings

    try:
        config = ImitationConfig(
            hidden_sizes=args.hidden,
            activation=args.activation,
            lr=args.lr,
            batch_size=args.batch_size,
            max_epochs=args.epochs,
            patience=args.patience,
            val_fraction=args.val_fraction,
            seed=args.seed,
        )
        nav = OBSERVATIONS[args.observation]
        demos = load_demos_for(args.demos, nav)
    except (DemoFormatError, ValueError) as exc:
        print(f"navlearn imitate train: {exc}", file=sys.stderr)
        return 2
    if len(demos) < 2:
        print("navlearn imitate train: need at least 2 demonstrations", file=sys.stderr)
        return 2
    n_actions = nav.robot.n_actions
    with Progress() as progress:
        bar = progress.add_task("epochs", total=config.max_epochs)

        def on_epoch(record: dict) -> None:
            progress.update(
                bar,
                advance=1,
                description=f"epoch {record['epoch']:3d} val loss {record['val_loss']:.3f} "
                f"acc {record['val_accuracy']:.3f}",
            )

        result = train_policy(
            demos, config, n_actions=n_actions, on_epoch=on_epoch, observation=observation_settings(nav)
        )
    out = save_trained(args.out, result, config, demos=str(Path(args.demos).resolve()))
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

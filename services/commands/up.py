"""`navlearn up`: learner + actors + evaluator on this machine for a bounded run."""

from __future__ import annotations

import argparse

from agents.nnql.config import NNQLConfig
from services.common.options import add_options
from services.learner.config import NNQL_REFUSED, learner_network
from services.ops.up_config import UpConfig
from worlds.own_env import ENV_TITLE, EnvConfig

DESCRIPTION = """\
Train NNQL the distributed way on one machine: check the arguments (maps included), compile the
robot world once (the first run on a machine: 35-40 s on 2 idle cores, 75-90 s on cores busy
with other work, with a progress line; later runs load the cache),
start the learner (hosting the Zenoh router on a free loopback port), --actors actor processes
of --envs robots each and the evaluator, show progress (one live line: what each process is
doing until the first transition, then the learner's status), and after --duration seconds of
training counted from the first transition (or --updates updates, or Ctrl-C) stop them in
order: actors, learner (final checkpoint), then the evaluator once it has measured the final
policy. Everything lands in --out (default runs/<run>): checkpoints/, policy/ (model.safetensors +
config.json: the version that scored best in the evaluator's evaluations, which play the validation
episodes, seed 1; --no-keep-best: the learner's last weights, the evaluator on the test episodes),
eval/learning_curve.png (time axis from the first launch, resumes marked) and
eval/evaluations.jsonl, tb/ (TensorBoard), logs/, summary.json. Running it again with the same --run
resumes from its checkpoint ("resumed from checkpoint N"). The NNQL
flags go to the learner. With --nirl the learner also trains NIRL, a demonstrator process
publishes demonstrations (the expert's --demo-episodes, or a --demos dataset once) and the
evaluator reports NIRL beside NNQL. Exit code 2 for a bad argument (before anything starts), 1 if
a process fails (its log tail is printed).

With --env every process runs a Gymnasium env with discrete actions instead of the robot world (an id,
module:Id or module:callable, --env-kwargs as JSON; nothing is compiled): the evaluator reports the
mean return, episode length and success where the env says it. How-to: docs/own-env.md.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "up",
        help="run learner + actors + evaluator on this machine (bounded run)",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_options(parser, UpConfig, "NAVLEARN_UP", "run")
    add_options(
        parser,
        NNQLConfig,
        "NAVLEARN_NNQL",
        "NNQL hyper-parameters (passed to the learner)",
        skip=("seed",),
        refuse=NNQL_REFUSED,
    )
    add_options(parser, EnvConfig, "NAVLEARN_ENV", ENV_TITLE)
    parser.set_defaults(func=main)


SMALL_EVALUATION = 100
"""episodes per family under which `up`'s final figures say that their interval is wide"""


def small_evaluation(last: dict) -> str | None:
    """A line saying that the final evaluation rests on few episodes (under SMALL_EVALUATION per
    family) and that its 95% intervals are too wide to compare with headline figures (500 episodes),
    or None when it does not."""
    counts = [m["episodes"] for final in last.values() for m in final["metrics"].values() if "success" in m]
    if not counts or min(counts) >= SMALL_EVALUATION:
        return None
    return (
        f"  note: {min(counts)} episodes per family: the intervals in [ ] are wide, so these rates "
        "cannot be told apart from figures within them (the recorded figures rest on 500); for a "
        "figure to compare, give --eval-episodes 200 or more, or run `navlearn evaluate` on the policy"
    )


def figure_lines(metrics: dict, model: str, version: int, seed: int) -> list[str]:
    """One line per family (or Gymnasium env) of an evaluation of ``model``'s ``version`` on the
    episodes of ``seed``."""
    from agents.evaluation.env_returns import table

    lines = []
    for family, m in metrics.items():
        if "return" in m:  # a Gymnasium --env
            lines.append(f"{model} {table({family: m})} (version {version}, seed {seed})")
            continue
        lines.append(
            f"{model} {family}: success {100 * m['success']['value']:.0f}% "
            f"[{100 * m['success']['low']:.0f}, {100 * m['success']['high']:.0f}], SPL {m['spl']:.2f} "
            f"(version {version}, {m['episodes']} held-out episodes, seed {seed})"
        )
    return lines


def main(args: argparse.Namespace) -> int:
    import logging
    import sys
    import time
    from contextlib import nullcontext

    from rich.console import Console
    from rich.live import Live
    from rich.text import Text

    from agents.evaluation.selection import TEST_SEED
    from services.common.options import OptionError, options_from_args
    from services.common.process import stop_on_signals
    from services.ops.status import progress_line
    from services.ops.up import ChildFailed, Up, checkpoint_number, local_dir
    from services.ops.up_config import check_config

    try:
        config = options_from_args(UpConfig, args, "NAVLEARN_UP")
        nnql = options_from_args(NNQLConfig, args, "NAVLEARN_NNQL", seed=config.seed)
        env = options_from_args(EnvConfig, args, "NAVLEARN_ENV")
        map_notes = check_config(config, env)
        # the learner's Q-network variant, now; with --env one copy is built: a bad id, kwargs or action
        # space refused with its sentence
        learner_network(nnql, config.observation, env)
    except (OptionError, ValueError) as exc:
        print(f"navlearn up: {exc}", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.WARNING, format="%(name)s %(levelname)s %(message)s")
    console = Console()
    up = Up(config, nnql, env)
    try:  # one `up` per run directory, held until this process ends (before anything is written)
        record = up.claim()
    except ValueError as exc:
        print(f"navlearn up: {exc}", file=sys.stderr)
        return 2
    limits = [
        f"{config.duration:.0f} s" * bool(config.duration),
        f"{config.updates} updates" * bool(config.updates),
    ]
    budget = " or ".join(b for b in limits if b) or "until Ctrl-C"
    demonstrator = ""
    if config.nirl:
        demonstrator = f" + demonstrator ({config.demos or config.demonstrator})"
    runs = f"observation {config.observation}" if env.own_world else f"env {env.signature()}"
    console.print(
        f"navlearn up: run [bold]{config.run}[/bold], learner{' (NNQL + NIRL)' * config.nirl} + "
        f"{config.actors} actors x {config.envs} robots{demonstrator} + evaluator on {up.endpoint}; "
        f"{runs}; "
        f"budget {budget} from the first transition; "
        f"outputs in {up.out}/",
        soft_wrap=True,
    )
    for note in map_notes:  # each map file's cell size and why (docs/maps.md)
        console.print(f"map {note}", soft_wrap=True, highlight=False)
    console.print(
        f"status from another terminal: [bold]{record.status_command()}[/bold] "
        f"(or, from this directory, `navlearn status{local_dir(up.out)}`)",
        soft_wrap=True,
        highlight=False,
    )
    # Compiled once here, before the processes start, rather than by each of them at once.
    if env.own_world:
        from services.common.warmup import compile_with_progress

        # a Gymnasium --env: nothing of the robot world runs
        seconds, compiled = compile_with_progress(console, config.maps)
        console.print(
            f"robot world compiled in {seconds:.0f} s (cached for later runs)"
            if compiled
            else f"robot world loaded from the compile cache in {seconds:.1f} s"
        )
    stop = stop_on_signals()
    resumed_version = up.final_version()  # the checkpoint's: the learner's first status is past it already
    up.start()
    start = time.monotonic()
    view, failed = None, None
    width = max(40, min(console.width, 80) - 1)

    # On a terminal one line updates in place (transient); in a log (pipe, file) a line every 10 s.
    live_or_not = (
        Live(console=console, auto_refresh=False, transient=True) if console.is_terminal else nullcontext()
    )
    with live_or_not as live:
        last_print = [0.0]
        said_resumed = [up.resumed_from is None]

        def show(current, elapsed, phases):
            if not said_resumed[0] and current and current["learner"]:
                learner = current["learner"]
                console.print(
                    f"resumed from checkpoint {checkpoint_number(up.resumed_from)} "
                    f"(version {resumed_version}, "
                    f"replay {learner['replay_sizes'].get('transitions', 0)})"
                )
                said_resumed[0] = True
            if elapsed is None:
                line = f"[wait {time.monotonic() - start:3.0f} s] {phases}"
            else:
                clock = f"{elapsed:3.0f}/{config.duration:.0f} s" if config.duration else f"{elapsed:3.0f} s"
                line = f"[{clock}] {progress_line(current, config.actors, width - len(clock) - 3)}"
            text = Text(line, no_wrap=True, overflow="ellipsis")
            text.truncate(width, overflow="ellipsis")
            if console.is_terminal:
                live.update(text, refresh=True)
            elif time.monotonic() - last_print[0] >= 10:
                console.print(text, highlight=False)
                last_print[0] = time.monotonic()

        try:
            view = up.watch(stop, show)
        except ChildFailed as exc:
            failed = exc.child
        console.print("stopping: actors, learner (checkpoint), evaluator (final evaluation)...")
        codes = up.stop_all()
    summary = up.write_outputs(view, codes, time.monotonic() - start)
    if failed is not None:
        console.print(
            f"[red]{failed.name} exited with code {failed.process.returncode}[/red]; last lines of "
            f"{failed.log_path}:\n{failed.tail()}"
        )
        return 1
    bad = {name: code for name, code in codes.items() if code not in (0, -15)}
    console.print(
        f"final policy version {summary['final_version']} after {summary['training_s']:.0f} s of "
        f"training ({summary['wall_time_s']:.0f} s in all)"
    )
    seed = summary["eval_seed"]
    for model, final in summary["last_evaluations"].items():
        for line in figure_lines(final["metrics"], model, final["policy_version"], seed):
            console.print(f"  {line}", highlight=False)
    if (few := small_evaluation(summary["last_evaluations"])) is not None:
        console.print(few, highlight=False)
    test = f"test it on the test episodes (seed {TEST_SEED}): navlearn evaluate --policy {up.out}/policy"
    if (kept := summary["kept"]) is not None:
        console.print(f"policy: version {kept['version']}, the best the evaluator measured; {test}")
        for line in figure_lines(kept["metrics"], "kept", kept["version"], kept["eval_seed"]):
            console.print(f"  {line}", highlight=False)
    elif summary["policy_version"] is not None:
        console.print(f"policy: the learner's last version {summary['policy_version']}; {test}")
    for name, path in summary["outputs"].items():
        console.print(f"  {name}: {path}")
    if bad:
        console.print(f"[red]processes exited with errors: {bad}[/red] (see {up.out}/logs/)")
        return 1
    return 0

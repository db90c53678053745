"""`navlearn status`: the learner's status and the processes alive, as a table or JSON."""

from __future__ import annotations

import argparse

from services.common.transport import add_zenoh_args


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "status",
        help="show the learner's status and which processes are alive",
        description=(
            "Query navlearn/<run>/status/learner (policy version, the observation it trains on, replay "
            "sizes, updates/s, transitions "
            "received and rejected by reason, per-actor rate and last seen, losses, last evaluation) and "
            "the liveliness tokens under navlearn/<run>/alive/ (learner, actors, demonstrators, "
            "evaluator), then print a table, or JSON with --json. With --actors, also ask every actor "
            "for its own status on navlearn/<run>/status/actor:<id> (outbox held/bound, unacknowledged "
            "and resent batches, time spent waiting for the learner and whether it is slowed by "
            "back-pressure, robot-steps/s, weights version). With --drives, also ask every navlearn drive "
            "and navlearn ros2-sim on status/drive:<id> and status/sim:<id> (state, goal, distance, last "
            "action, stale inputs; pose and collision). Exit code 1 if the learner does not "
            "answer (with --drives: and no drive or sim answers either), 2 if no router answers within "
            "--connect-timeout seconds (both name the endpoint "
            "and the run they asked)."
        ),
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    parser.add_argument(
        "--actors",
        action="store_true",
        help="also query each actor's own status (outbox, back-pressure, weights version); "
        "JSON key actor_status",
    )
    parser.add_argument(
        "--drives",
        action="store_true",
        help="also query navlearn drive and navlearn ros2-sim processes (state, goal, distance, last "
        "action, stale inputs); JSON key robots. Give the robot's router with --connect",
    )
    parser.add_argument(
        "--watch",
        nargs="?",
        const=2.0,
        type=float,
        metavar="SECONDS",
        help="refresh every SECONDS (default 2) until Ctrl-C; with --json prints one object per line",
    )
    parser.add_argument(
        "--timeout", type=float, default=3.0, help="seconds to wait for the learner's answer (default 3)"
    )
    parser.add_argument(
        "--dir",
        metavar="DIR",
        help="the run directory of a `navlearn up` (its --out): ask the run it records in DIR/up.json. "
        "Without --dir, --connect or --run, the live `up` run recorded in this directory or in "
        "runs/* below it is asked (default: that one, if any)",
    )
    add_zenoh_args(parser, default_mode="client", connect_timeout=3.0)
    parser.set_defaults(func=main)


def recorded_run(args: argparse.Namespace) -> tuple[dict, str]:
    """Settings overrides (connect, run) from a `navlearn up` run directory, and a note for the
    failure message: --dir's record, or with no --connect/--run (flags or environment) the live run
    found here (services.ops.run_record); none when the endpoint and run were given."""
    import os

    from services.ops.run_record import choose_record, find_records

    given = (
        args.zenoh_connect
        or args.zenoh_run
        or os.environ.get("NAVLEARN_CONNECT")
        or os.environ.get("NAVLEARN_RUN")
    )
    if given and not args.dir:
        return {}, ""
    record = choose_record(args.dir)
    if record is None:
        stale = find_records()
        note = (
            f" (the newest `navlearn up` here, in {stale[0].out}, has exited; its run was {stale[0].run})"
            if stale
            else ""
        )
        return {}, note
    overrides = {"connect": [record.endpoint], "run": record.run}
    if args.zenoh_connect:
        overrides.pop("connect")
    if args.zenoh_run:
        overrides.pop("run")
    if record.live():
        note = (
            f" (the `navlearn up` of {record.out}, pid {record.pid}, is running: its learner answers "
            "once the world is compiled and it has started)"
        )
    else:
        note = f" (the `navlearn up` of {record.out} has exited)"
    return overrides, note


def main(args: argparse.Namespace) -> int:
    import json
    import sys
    import time

    from services.common.transport import TransportError, open_session, settings_from_args
    from services.ops.status import (
        learner_runs,
        no_learner_hint,
        query_alive,
        query_status,
        render,
        render_robots,
        robot_statuses,
        status_dict,
    )

    note = ""
    try:
        overrides, note = recorded_run(args)
        settings = settings_from_args(args, **overrides)
        session = open_session(settings)
    except (TransportError, ValueError) as exc:
        print(f"navlearn status: {exc}{note}", file=sys.stderr)
        return 2

    def snapshot() -> dict:
        status = query_status(session, settings.run, timeout=args.timeout)
        view = status_dict(status, query_alive(session, settings.run, timeout=min(args.timeout, 1.0)))
        if args.actors:
            from services.actor.status import actor_status_dicts, query_actor_statuses

            statuses = query_actor_statuses(session, settings.run, timeout=min(args.timeout, 2.0))
            view["actor_status"] = actor_status_dicts(statuses)
        if args.drives:
            view["robots"] = robot_statuses(session, settings.run, timeout=min(args.timeout, 2.0))
        return view

    def show(view: dict):
        from rich.console import Group

        parts = [render(view)]
        if "actor_status" in view:
            from services.actor.status import render_actor_statuses

            parts.append(render_actor_statuses(view["actor_status"]))
        if "robots" in view:
            parts.append(render_robots(view["robots"]))
        return parts[0] if len(parts) == 1 else Group(*parts)

    with session:
        try:
            if args.watch is None:
                view = snapshot()
                if args.json:
                    print(json.dumps(view))
                else:
                    from rich.console import Console

                    Console().print(show(view))
                if view["learner"] is None and not view.get("robots"):
                    hint = no_learner_hint(
                        settings.run, learner_runs(session, timeout=min(args.timeout, 1.0))
                    )
                    print(
                        f"navlearn status: no answer on navlearn/{settings.run}/status/learner via "
                        f"{settings.where()} within {args.timeout:g} s; {hint}{note}",
                        file=sys.stderr,
                    )
                    return 1
                return 0
            if args.json:
                while True:
                    print(json.dumps(snapshot()), flush=True)
                    time.sleep(args.watch)
            from rich.live import Live

            with Live(show(snapshot()), auto_refresh=False) as live:
                while True:
                    time.sleep(args.watch)
                    live.update(show(snapshot()), refresh=True)
        except KeyboardInterrupt:
            return 0

"""Reading the learner's status over Zenoh and showing it (``navlearn status``, ``navlearn up``)."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from typing import Any

from protocols import keys
from protocols.codec import decode
from protocols.errors import ProtocolError
from protocols.messages import EvalReport, StatusReport


def _eval_part(family: str, fam: dict[str, Any]) -> str:
    """A family's figure in the progress line: ``u75%`` (first letter, success), or for a Gymnasium
    --env ``return 212.3`` (and its success where it says one)."""
    if fam.get("return") is None:
        return f"{family[0]}{100 * fam['success']:.0f}%"
    success = "" if fam.get("success") is None else f" {100 * fam['success']:.0f}%"
    return f"return {fam['return']:.1f}{success}"


def eval_summary(evaluator: str, report: EvalReport, arrived: float) -> dict[str, Any]:
    """The part of an EvalReport the learner keeps for its status: per family success, SPL, path ratio
    (navlearn's world) or mean return (a Gymnasium --env: the family is the env id)."""
    families = {}
    for family, metrics in report.metrics.items():
        success = metrics.get("success")
        returns = metrics.get("return")
        families[family] = {
            "success": success.get("value") if isinstance(success, dict) else success,
            "spl": metrics.get("spl"),
            "path_ratio": metrics.get("path_ratio"),
            "episodes": metrics.get("episodes"),
        }
        if isinstance(returns, dict):
            families[family]["return"] = returns.get("mean")
    return {
        "evaluator": evaluator,
        "model": report.model,
        "policy_version": report.policy_version,
        "received": arrived,
        "families": families,
    }


def status_replies(session, key: str, timeout: float) -> Iterator[tuple[str, StatusReport]]:
    """(last key chunk, status) of each valid StatusReport answer to a get on ``key``."""
    for reply in session.get(key, timeout=timeout):
        if reply.ok is None:
            continue
        try:
            message = decode(reply.ok.payload.to_bytes())
        except ProtocolError:
            continue
        if isinstance(message, StatusReport):
            yield str(reply.ok.key_expr).rsplit("/", 1)[-1], message


def query_status(session, run: str, timeout: float = 3.0) -> StatusReport | None:
    """The learner's answer on ``status/learner``, or None if no learner answered in time."""
    return next((message for _, message in status_replies(session, keys.status(run), timeout)), None)


def robot_statuses(session, run: str, timeout: float = 2.0) -> dict[str, dict]:
    """``drive:<id>`` / ``sim:<id>`` -> the ``robot`` part of each status answered under
    ``status/`` by ``navlearn drive`` and ``navlearn ros2-sim`` (``navlearn status --drives``)."""
    found = {}
    prefixes = (keys.DRIVE_STATUS_PREFIX, keys.SIM_STATUS_PREFIX)
    for name, message in status_replies(session, keys.everything(run, "status"), timeout):
        if message.robot is not None and name.startswith(prefixes):
            found[name] = message.robot
    return dict(sorted(found.items()))


def render_robots(robots: dict[str, dict]):
    """A rich table of :func:`robot_statuses`: one row per drive or simulated robot."""
    from rich.table import Table

    table = Table(title="robots (navlearn drive, navlearn ros2-sim)")
    for column in (
        "name",
        "state",
        "goal",
        "distance m",
        "last action",
        "actions",
        "stale",
        "pose",
        "detail",
    ):
        table.add_column(column)
    for name, robot in robots.items():
        collided = robot.get("collided")
        state = robot.get("state") or ("collided" if collided else "running")
        table.add_row(
            name,
            state,
            _fmt(robot.get("goal")),
            _fmt(robot.get("distance")),
            _fmt(robot.get("last_action")),
            _fmt(robot.get("actions")),
            ", ".join(robot.get("stale") or []) or "-",
            _fmt(robot.get("pose")),
            robot.get("detail") or "",
        )
    return table


def query_alive(session, run: str, timeout: float = 2.0) -> list[tuple[str, str]]:
    """(role, id) of every process holding a liveliness token in ``run``, sorted."""
    found = set()
    for reply in session.liveliness().get(keys.everything(run, "alive"), timeout=timeout):
        if reply.ok is None:
            continue
        try:
            found.add(tuple(keys.parse(reply.ok.key_expr).names))
        except ProtocolError:
            continue
    return sorted(found)


def learner_runs(session, timeout: float = 1.0) -> list[str]:
    """Runs in which a learner holds its liveliness token, sorted (empty if none, or if an ACL hides them)."""
    runs = set()
    for reply in session.liveliness().get(keys.alive_in_every_run("learner"), timeout=timeout):
        if reply.ok is None:
            continue
        try:
            runs.add(keys.parse(reply.ok.key_expr).run)
        except ProtocolError:
            continue
    return sorted(runs)


def no_learner_hint(run: str, runs: list[str]) -> str:
    """Why no learner answers on ``run``, from the runs that do have one (``learner_runs``)."""
    if runs:
        listed = ", ".join(repr(r) for r in runs)
        return f"no learner on run {run!r}, but on {listed}: give --run {runs[0]} (or start one on {run!r})"
    return (
        f"no learner on run {run!r} holds a liveliness token here: start one (navlearn learner --run {run} "
        "or navlearn up), or check --connect, --run and the router's ACL"
    )


def status_dict(status: StatusReport | None, alive: list[tuple[str, str]], now: float | None = None) -> dict:
    """One JSON-able view of the run: the learner's status (None if it did not answer) and who is alive."""
    now = time.time() if now is None else now
    processes: dict[str, list[str]] = {}
    for role, ident in alive:
        processes.setdefault(role, []).append(ident)
    out: dict[str, Any] = {"time": now, "alive": processes, "learner": None}
    if status is None:
        return out
    alive_actors = set(processes.get("actor", []))
    actors = {}
    for actor in sorted(set(status.actors_last_seen) | alive_actors):
        last_seen = status.actors_last_seen.get(actor)
        actors[actor] = {
            "alive": actor in alive_actors,
            "transitions": status.counters.get(f"transitions/{actor}", 0),
            "transitions_per_s": status.rates.get(f"transitions_per_s/{actor}", 0.0),
            "last_seen_s_ago": None if last_seen is None else round(now - last_seen, 1),
        }
    out["learner"] = {
        "sender": status.sender,
        "observation": status.observation,
        "versions": status.versions,
        "replay_sizes": status.replay_sizes,
        "counters": {k: v for k, v in status.counters.items() if not k.startswith("transitions/")},
        "rates": {k: v for k, v in status.rates.items() if not k.startswith("transitions_per_s/")},
        "losses": {k: (v if math.isfinite(v) else str(v)) for k, v in status.losses.items()},
        "actors": actors,
        "demos": demos_per_source(status.counters),
        "last_eval": status.last_eval,
    }
    return out


def demos_per_source(counters: dict[str, int]) -> dict[str, dict[str, int]]:
    """Source (astar, human, file) -> demonstration episodes and steps the learner has stored."""
    sources: dict[str, dict[str, int]] = {}
    for name, value in counters.items():
        kind, _, source = name.partition("/")
        if kind in ("demo_episodes", "demo_steps") and source:
            sources.setdefault(source, {"episodes": 0, "steps": 0})[kind.removeprefix("demo_")] = value
    return dict(sorted(sources.items()))


def _fmt(value: Any, spec: str = ".3g") -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return format(value, spec)
    return str(value)


def _short(n: float) -> str:
    """12, 1.2k, 34k, 1.2M: a count in at most 4 characters."""
    for limit, suffix in ((1e6, "M"), (1e3, "k")):
        if abs(n) >= limit:
            scaled = n / limit
            return f"{scaled:.1f}{suffix}" if scaled < 10 else f"{scaled:.0f}{suffix}"
    return f"{n:.0f}"


def progress_line(view: dict, actors_expected: int | None = None, width: int = 68) -> str:
    """One line of at most ``width`` characters for a live display: version, updates/s,
    transitions/s, replay, policy lag, actors if some are missing, rejections if any, and the
    last evaluation's success per family (first letter: unseen, dynamic, movingai); what does
    not fit is cut, marked by "..."."""
    learner = view.get("learner")
    if learner is None:
        return "waiting for the learner's status..."
    rates, counters = learner["rates"], learner["counters"]
    version = next(iter(learner["versions"].values()), 0)
    replay = learner["replay_sizes"].get("transitions", 0)
    parts = [f"v{version}"]
    if "nirl" in learner["versions"]:
        demos = _short(learner["replay_sizes"].get("demos", 0))
        parts.append(f"nirl v{learner['versions']['nirl']} demos {demos}")
    if counters.get("storage_error"):  # first, so that it is never cut off
        parts.append("STORAGE ERROR: not acknowledging (see the learner's log)")
    parts += [
        f"{rates.get('updates_per_s', 0):.0f} upd/s",
        f"{_short(rates.get('transitions_per_s', 0))} tr/s",
        f"replay {_short(replay)}",
        f"lag {rates.get('policy_lag', 0):.1f}",
    ]
    actors = len(view["alive"].get("actor", []))
    if actors_expected is None or actors < actors_expected:
        parts.append(f"actors {actors}" + (f"/{actors_expected}" if actors_expected else ""))
    if counters.get("transitions_rejected", 0):
        parts.append(f"rejected {_short(counters['transitions_rejected'])}")
    evaluation = learner.get("last_eval")
    if evaluation:
        success = " ".join(
            _eval_part(family, fam)
            for family, fam in evaluation.get("families", {}).items()
            if fam.get("success") is not None or fam.get("return") is not None
        )
        model = evaluation.get("model", "")
        parts.append(f"eval{' ' + model if model and model != 'nnql' else ''} {success}")
    line = "  ".join(parts)
    return line if len(line) <= width else line[: width - 3] + "..."


def render(view: dict):
    """A rich renderable: summary, actors, rejections and the last evaluation."""
    from rich.console import Group
    from rich.table import Table

    learner = view.get("learner")
    alive = ", ".join(f"{role}: {' '.join(ids)}" for role, ids in sorted(view["alive"].items())) or "none"
    if learner is None:
        summary = Table(title="navlearn status", show_header=False)
        summary.add_row("learner", "no answer on status/learner")
        summary.add_row("alive", alive)
        return summary
    summary = Table(title=f"learner {learner['sender']}", show_header=False)
    if learner.get("observation"):
        summary.add_row("observation", learner["observation"])
    for model, version in learner["versions"].items():
        summary.add_row(f"policy version ({model})", str(version))
    for name, size in learner["replay_sizes"].items():
        summary.add_row(f"replay: {name}", str(size))
    for name, value in sorted(learner["rates"].items()):
        summary.add_row(name.replace("_", " "), _fmt(value))
    for name, value in sorted(learner["counters"].items()):
        summary.add_row(name.replace("_", " "), str(value))
    for name, value in sorted(learner["losses"].items()):
        summary.add_row(f"loss: {name}", _fmt(value, ".4g"))
    summary.add_row("alive", alive)
    actors = Table(title="actors")
    for column in ("actor", "alive", "transitions", "transitions/s", "last seen (s ago)"):
        actors.add_column(column, justify="left" if column == "actor" else "right")
    for name, actor in learner["actors"].items():
        actors.add_row(
            name,
            "yes" if actor["alive"] else "[red]gone[/red]",
            str(actor["transitions"]),
            _fmt(actor["transitions_per_s"], ".0f"),
            _fmt(actor["last_seen_s_ago"]),
        )
    parts = [summary, actors]
    if learner.get("demos"):
        demos = Table(title="demos per source")
        for column in ("source", "episodes", "steps"):
            demos.add_column(column, justify="left" if column == "source" else "right")
        for source, count in learner["demos"].items():
            demos.add_row(source, str(count["episodes"]), str(count["steps"]))
        parts.append(demos)
    evaluation = learner.get("last_eval")
    if evaluation:
        table = Table(
            title=f"last evaluation: {evaluation.get('model', '')} version {evaluation['policy_version']} "
            f"by {evaluation['evaluator']}"
        )
        for column in ("family", "episodes", "success", "SPL", "path / A*"):
            table.add_column(column, justify="left" if column == "family" else "right")
        for family, fam in evaluation.get("families", {}).items():
            success = fam.get("success")
            table.add_row(
                family,
                _fmt(fam.get("episodes")),
                "-" if success is None else f"{100 * success:.0f}%",
                _fmt(fam.get("spl"), ".2f"),
                _fmt(fam.get("path_ratio"), ".2f"),
            )
        parts.append(table)
    return Group(*parts)

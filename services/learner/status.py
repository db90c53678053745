"""The learner's status snapshot (protocols' StatusReport), answered on ``status/learner``."""

from __future__ import annotations

from protocols.messages import StatusReport
from services.learner.state import LearnerParts
from services.learner.stats import LearnerTally


def build_status(parts: LearnerParts, model: str, observation: str, sender: str, seq: int) -> StatusReport:
    """Counters (incl. rejections by reason and the write-ahead log's), rates, versions, replay sizes,
    per-actor totals and last seen, losses, the last evaluation and the observation of a learner
    service's parts."""
    tally, learner = parts.tally, parts.learner
    counters = {
        **tally.counters,
        **parts.inbox.counts(),
        **parts.storage.counters(),
        "updates": learner.version,
    }
    if parts.durable is not None:
        counters.update(parts.durable.status_counters())
    counters["transitions_rejected"] = sum(v for k, v in counters.items() if k.startswith("rejected/"))
    rates = {
        "updates_per_s": tally.update_rate.rate(),
        "transitions_per_s": tally.insert_rate.rate(),
        "policy_lag": tally.lags.mean(),
        "update_to_data": parts.limiter.updates / max(parts.limiter.inserts, 1),
    }
    for actor, stats in tally.actors.items():
        rates[f"transitions_per_s/{actor}"] = stats.rate.rate()
        counters[f"transitions/{actor}"] = stats.transitions
    versions = {model: learner.version}
    losses = {k.removeprefix("losses/"): v for k, v in tally.metrics.items() if k.startswith("losses/")}
    if parts.nirl is not None:
        nirl_counters, nirl_losses = parts.nirl.status_fields()
        counters.update(nirl_counters)
        losses.update(nirl_losses)
        versions["nirl"] = parts.nirl.version
    return StatusReport(
        sender=sender,
        seq=seq,
        counters=counters,
        rates=rates,
        versions=versions,
        replay_sizes={"transitions": len(learner.replay), "demos": len(parts.demos)},
        actors_last_seen={a: s.last_seen for a, s in tally.actors.items() if s.last_seen},
        losses=losses,
        last_eval=tally.last_eval,
        observation=observation,
    )


def status_charts(status: StatusReport, metrics: dict[str, float]) -> dict[str, float]:
    """TensorBoard scalars of a status snapshot and the newest update's losses."""
    charts = {
        "charts/updates_per_s": status.rates["updates_per_s"],
        "charts/transitions_per_s": status.rates["transitions_per_s"],
        "charts/policy_lag": status.rates["policy_lag"],
        "charts/replay_size": status.replay_sizes["transitions"],
        "charts/update_to_data": status.rates["update_to_data"],
    }
    charts.update({k: v for k, v in metrics.items() if k.startswith("losses/")})
    charts.update({k: v for k, v in status.losses.items() if k.startswith("nirl/")})  # learned reward too
    return charts


def progress_line(status: StatusReport, tally: LearnerTally) -> str:
    """The learner's periodic log line."""
    rates, counters = status.rates, status.counters
    return (
        f"version {counters['updates']} | replay {status.replay_sizes['transitions']}"
        f" | {rates['updates_per_s']:.0f} upd/s | {rates['transitions_per_s']:.0f} transitions/s"
        f" | lag {rates['policy_lag']:.1f} | actors {len(tally.actors)}"
        f" | rejected {counters['transitions_rejected']}"
        f" | td {tally.metrics.get('losses/td_loss', float('nan')):.4g}"
    )

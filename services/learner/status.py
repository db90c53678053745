"""The learner's status snapshot (protocols' LearnerStatus), answered on ``status/learner``."""

from __future__ import annotations

from typing import Any

from protocols.messages import LearnerStatus


def build_status(service: Any, seq: int) -> LearnerStatus:
    """Counters (incl. rejections by reason and the write-ahead log's), rates, versions, replay sizes,
    per-actor totals and last seen, losses and the last evaluation of a LearnerService."""
    counters = {**service.counters, **service.inbox.counts(), "updates": service.learner.version}
    if service.durable is not None:
        counters.update(service.durable.status_counters())
    counters["transitions_rejected"] = sum(v for k, v in counters.items() if k.startswith("rejected/"))
    rates = {
        "updates_per_s": service.update_rate.rate(),
        "transitions_per_s": service.insert_rate.rate(),
        "policy_lag": service.lags.mean(),
        "update_to_data": service.limiter.updates / max(service.limiter.inserts, 1),
    }
    for actor, stats in service.actors.items():
        rates[f"transitions_per_s/{actor}"] = stats.rate.rate()
        counters[f"transitions/{actor}"] = stats.transitions
    versions = {service.config.model: service.learner.version}
    losses = {k.removeprefix("losses/"): v for k, v in service.metrics.items() if k.startswith("losses/")}
    if service.nirl is not None:
        nirl_counters, nirl_losses = service.nirl.status_fields()
        counters.update(nirl_counters)
        losses.update(nirl_losses)
        versions["nirl"] = service.nirl.version
    return LearnerStatus(
        sender=service.sender,
        seq=seq,
        counters=counters,
        rates=rates,
        versions=versions,
        replay_sizes={"transitions": len(service.learner.replay), "demos": len(service.demos)},
        actors_last_seen={a: s.last_seen for a, s in service.actors.items() if s.last_seen},
        losses=losses,
        last_eval=service.last_eval,
    )

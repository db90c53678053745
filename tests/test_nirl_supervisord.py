"""A demonstrator and a NIRL learner under a real supervisord with the shipped deploy/supervisord.conf
(settings through the services' environment variables, as README and deploy/systemd/navlearn.env say):
the demonstrator starts on `supervisorctl start`, its expert episodes are acknowledged (it exits 0 and
stays stopped), status counts them per source, NIRL's version grows and the evaluator reports NIRL."""

from __future__ import annotations

import json
import time

import pytest
from test_services_supervisord import Cluster

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(600)]
EPISODES = 3
NIRL = {
    "NAVLEARN_LEARNER_NIRL": "1",
    "NAVLEARN_NIRL_HIDDEN_SIZES": "16",
    "NAVLEARN_NIRL_REWARD_HIDDEN_SIZES": "16",
    "NAVLEARN_NIRL_BATCH_SIZE": "16",
    "NAVLEARN_NIRL_DEMO_BATCH_SIZE": "16",
    "NAVLEARN_NIRL_WARMSTART_UPDATES": "40",
    "NAVLEARN_NIRL_Q_UPDATES": "20",
    "NAVLEARN_NIRL_REWARD_UPDATES": "5",
    "NAVLEARN_EVALUATOR_COMPARE": "nirl",
    "NAVLEARN_DEMONSTRATOR_SOURCE": "astar",
    "NAVLEARN_DEMONSTRATOR_EPISODES": str(EPISODES),
    "NAVLEARN_DEMONSTRATOR_RATE": "0",
    "NAVLEARN_DEMONSTRATOR_MAPS": "rooms:10",
}


def test_supervised_demonstrator_feeds_a_nirl_learner(tmp_path):
    cluster = Cluster(tmp_path / "home", extra=NIRL, actors=1)
    try:
        cluster.connect()
        cluster.wait_for("the learner", lambda v: "nirl" in v["learner"]["versions"], timeout=240)
        assert "STOPPED" in cluster.ctl("status", "demonstrator", check=False)  # autostart=false
        cluster.ctl("start", "demonstrator")
        view = cluster.wait_for(
            "the expert's episodes and NIRL training on them",
            lambda v: (
                v["learner"]["demos"].get("astar", {}).get("episodes") == EPISODES
                and v["learner"]["versions"]["nirl"] > 40
            ),
            timeout=240,
        )
        assert view["learner"]["demos"]["astar"]["steps"] == view["learner"]["replay_sizes"]["demos"]
        assert any(name.startswith("nirl/") for name in view["learner"]["losses"])
        # every batch acknowledged: the demonstrator exited 0, and supervisord leaves it stopped
        deadline = time.monotonic() + 60
        while "EXITED" not in (state := cluster.ctl("status", "demonstrator", check=False)):
            assert time.monotonic() < deadline, state
            time.sleep(1.0)
        assert "FATAL" not in state and "BACKOFF" not in state
        evaluations = cluster.home / "eval" / "evaluations.jsonl"
        deadline = time.monotonic() + 180
        while True:
            lines = evaluations.read_text().splitlines() if evaluations.exists() else []
            if any(json.loads(line)["model"] == "nirl" for line in lines):
                break
            assert time.monotonic() < deadline, f"no NIRL evaluation in {evaluations}: {lines}"
            time.sleep(2.0)
    finally:
        cluster.close()

"""Per-process ACL from `navlearn credentials`, enforced by a real router on 127.0.0.1: actor a1 may
publish transitions/a1 but not transitions/a2 nor weights; the learner's weights and acks reach it."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from protocols import keys
from services.common.transport import TransportError, ZenohSettings, open_session
from services.ops.acl import Deployment, access_control
from tests.test_wire_zenoh import REPO, start_router, stop

RUN = "acl"


def credentials(out: Path) -> dict[str, str]:
    done = subprocess.run(
        [sys.executable, "-m", "services.cli", "credentials", "--out", str(out), "--run", RUN,
         "--actors", "a1", "a2", "--demonstrators", "d1=astar", "--evaluators", "ev1"],
        capture_output=True, text=True, timeout=60, check=True,
    )  # fmt: skip
    assert "wrote" in done.stdout
    return {p.name: str(p) for p in out.iterdir()}


def test_generated_files_are_private_and_rules_are_per_process(tmp_path: Path) -> None:
    files = credentials(tmp_path)
    for name in ("users.txt", "a1.credentials", "learner.credentials", "d1.credentials"):
        assert (Path(files[name]).stat().st_mode & 0o777) == 0o600
    users = dict(line.split(":", 1) for line in Path(files["users.txt"]).read_text().splitlines())
    assert set(users) == {"learner", "a1", "a2", "d1", "ev1", "status"}
    assert Path(files["a1.credentials"]).read_text().strip() == f"a1:{users['a1']}"
    assert users["a1"] != users["a2"]
    acl = access_control(Deployment(run=RUN, actors=["a1"], cert_names=True))
    publish = next(r for r in acl["rules"] if r["id"] == "actor-a1-publish")
    assert publish["key_exprs"] == [f"navlearn/{RUN}/transitions/a1", f"navlearn/{RUN}/alive/actor/a1"]
    assert {"id": "actor-a1", "usernames": ["a1"], "cert_common_names": ["a1"]} in acl["subjects"]
    with pytest.raises(ValueError, match="used twice"):
        access_control(Deployment(actors=["learner"]))


def test_the_shipped_default_acl_is_the_generated_one() -> None:
    import zenoh

    shipped = zenoh.Config.from_file(str(REPO / "deploy" / "router-secure.json5"))
    expected = Deployment(
        run="default", actors=["actor1", "actor2"], demonstrators=["astar", "human"], evaluators=["evaluator"]
    )
    assert _without_nones(json.loads(shipped.get_json("access_control"))) == access_control(expected)


def _without_nones(value):
    """Zenoh fills the optional fields it knows with null; compare only what is set."""
    if isinstance(value, dict):
        return {k: _without_nones(v) for k, v in value.items() if v is not None}
    if isinstance(value, list):
        return [_without_nones(v) for v in value]
    return value


@pytest.mark.integration
@pytest.mark.timeout(90)
def test_an_actor_publishes_only_its_own_transitions(tmp_path: Path) -> None:
    files = credentials(tmp_path)
    endpoint, proc, _ = start_router("--auth-dictionary", files["users.txt"], "--acl", files["acl.json5"])

    def session(user: str):
        return open_session(
            ZenohSettings(
                connect=[endpoint], connect_timeout=10, run=RUN, credentials_file=files[f"{user}.credentials"]
            )
        )

    try:
        with pytest.raises(TransportError):  # a1's password is not a2's
            wrong = Path(tmp_path / "wrong.credentials")
            wrong.write_text("a2:" + Path(files["a1.credentials"]).read_text().split(":", 1)[1])
            open_session(ZenohSettings(connect=[endpoint], connect_timeout=1, credentials_file=str(wrong)))
        at_learner: list[tuple[str, bytes]] = []
        at_actor: list[tuple[str, bytes]] = []
        own, other = keys.transitions(RUN, "a1"), keys.transitions(RUN, "a2")
        weights, acks = keys.weights(RUN, "nnql"), keys.acks(RUN, "a1")
        with session("learner") as learner, session("a1") as actor:
            learner.declare_subscriber(
                f"navlearn/{RUN}/**", lambda s: at_learner.append((str(s.key_expr), s.payload.to_bytes()))
            )
            learner.declare_queryable(weights, lambda q: q.reply(weights, b"queried weights"))
            actor.declare_subscriber(
                weights, lambda s: at_actor.append((str(s.key_expr), s.payload.to_bytes()))
            )
            actor.declare_subscriber(acks, lambda s: at_actor.append((str(s.key_expr), s.payload.to_bytes())))
            deadline = time.monotonic() + 15
            while time.monotonic() < deadline and not (
                (own, b"mine") in at_learner and (weights, b"real") in at_actor and (acks, b"ack") in at_actor
            ):
                actor.put(other, b"forged")
                actor.put(weights, b"forged")
                actor.put(own, b"mine")
                learner.put(weights, b"real")
                learner.put(acks, b"ack")
                time.sleep(0.1)
            replies = [r.ok.payload.to_bytes() for r in actor.get(weights, timeout=5) if r.ok is not None]
            own_status, learner_status = keys.actor_status(RUN, "a1"), keys.status(RUN)
            actor.declare_queryable(own_status, lambda q: q.reply(own_status, b"a1 status"))
            actor.declare_queryable(learner_status, lambda q: q.reply(learner_status, b"forged status"))
            with session("status") as operator:
                time.sleep(0.5)
                answers = {
                    str(r.ok.key_expr): r.ok.payload.to_bytes()
                    for r in operator.get(f"navlearn/{RUN}/status/*", timeout=3)
                    if r.ok is not None
                }
            time.sleep(0.3)
        assert (own, b"mine") in at_learner
        assert (other, b"forged") not in at_learner  # a1 may not publish as a2
        assert (weights, b"forged") not in at_learner  # nor weights
        assert (weights, b"real") in at_actor and (acks, b"ack") in at_actor
        assert replies == [b"queried weights"]  # it may ask the learner for the newest weights
        assert answers == {own_status: b"a1 status"}  # an actor answers its own status, not the learner's
    finally:
        stop(proc)

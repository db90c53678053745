"""Per-process credentials and Zenoh access control (ACL) rules for one navlearn deployment.

Zenoh's ACL cannot substitute a user name into a key expression, so "an actor may
only publish ``transitions/<its own id>``" takes one subject and one set of rules per
actor. ``access_control(Deployment(...))`` builds them from the process ids, and
``write_deployment`` writes what a router and each process need: ``users.txt`` (the
router's ``user:password`` dictionary), ``<user>.credentials`` per process (one
``user:password`` line, mode 0600) and ``acl.json5`` (the ``access_control`` section,
for ``navlearn router --acl``). A process's user name is its id:

* the learner (``learner``) may do anything under ``navlearn/<run>/``;
* actor ``a`` publishes ``transitions/a`` and its token ``alive/actor/a``, receives and
  asks for ``weights/*``, receives ``acks/a`` and answers ``status/actor:a``;
* demonstrator ``d`` (``d`` or ``d=source``) publishes ``demos/<source>`` and its token
  ``alive/demonstrator/d``, receives ``acks/<source>`` and sees whether a learner is alive;
* evaluator ``e`` publishes ``eval/e`` and its token, receives and asks for ``weights/*``;
* operators (``status``) query ``status/*`` and see who is alive.

With ``cert_names`` a subject also requires the TLS client certificate's common name
to be the id (Zenoh ANDs a subject's attributes): user/password *and* mutual TLS.
"""

from __future__ import annotations

import json
import secrets
from dataclasses import dataclass, field
from pathlib import Path

from protocols import keys
from services.ops.secret_files import write_private


@dataclass
class Deployment:
    """The processes of one run; each id is also that process's Zenoh user name."""

    run: str = "default"
    learner: str = "learner"
    actors: list[str] = field(default_factory=list)
    demonstrators: list[str] = field(default_factory=list)
    """``id`` (publishing demos/<id>) or ``id=source`` (publishing demos/<source>)"""
    evaluators: list[str] = field(default_factory=list)
    operators: list[str] = field(default_factory=lambda: ["status"])
    """users that may only run ``navlearn status``"""
    cert_names: bool = False
    """also require the TLS client certificate common name to equal the id (mutual TLS)"""

    def demonstrator_sources(self) -> list[tuple[str, str]]:
        out = []
        for entry in self.demonstrators:
            ident, _, source = entry.partition("=")
            out.append((ident, source or ident))
        return out

    def users(self) -> list[str]:
        """Every user name, checked: valid key chunks and no name in two roles."""
        names = [
            self.learner,
            *self.actors,
            *(d for d, _ in self.demonstrator_sources()),
            *self.evaluators,
            *self.operators,
        ]
        for name in names:
            keys.check_name(name, "process id")
        for _, source in self.demonstrator_sources():
            keys.check_name(source, "demonstration source")
        keys.check_name(self.run, "run")
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ValueError(f"each process needs its own id; used twice: {', '.join(duplicates)}")
        return names


def _rule(ident: str, messages: list[str], flow: str, key_exprs: list[str]) -> dict:
    return {"id": ident, "messages": messages, "flows": [flow], "permission": "allow", "key_exprs": key_exprs}


def _role_rules(d: Deployment) -> dict[str, tuple[str, list[dict]]]:
    """subject id -> (user name, its rules)."""
    p = keys.prefix(d.run)
    everything = [
        "put", "delete", "declare_subscriber", "declare_queryable", "query", "reply",
        "liveliness_token", "declare_liveliness_subscriber", "liveliness_query",
    ]  # fmt: skip
    out: dict[str, tuple[str, list[dict]]] = {
        f"learner-{d.learner}": (
            d.learner,
            [
                _rule(f"learner-{d.learner}-in", everything, "ingress", [f"{p}/**"]),
                _rule(f"learner-{d.learner}-out", everything, "egress", [f"{p}/**"]),
            ],
        )
    }
    for a in d.actors:
        own = [f"{p}/transitions/{a}", f"{p}/alive/actor/{a}"]
        status = [keys.actor_status(d.run, a)]
        out[f"actor-{a}"] = (
            a,
            [
                _rule(f"actor-{a}-publish", ["put", "liveliness_token"], "ingress", own),
                _rule(
                    f"actor-{a}-follow",
                    ["declare_subscriber"],
                    "ingress",
                    [f"{p}/weights/*", f"{p}/acks/{a}"],
                ),
                _rule(f"actor-{a}-ask", ["query"], "ingress", [f"{p}/weights/*"]),
                _rule(f"actor-{a}-receive", ["put"], "egress", [f"{p}/weights/*", f"{p}/acks/{a}"]),
                _rule(f"actor-{a}-answers", ["reply"], "egress", [f"{p}/weights/*"]),
                _rule(f"actor-{a}-status", ["declare_queryable", "reply"], "ingress", status),
                # queries reach it as sent: `status/*` (navlearn status --actors) or its own key
                _rule(f"actor-{a}-status-asked", ["query"], "egress", [keys.everything(d.run, "status")]),
            ],
        )
    for ident, source in d.demonstrator_sources():
        own = [f"{p}/demos/{source}", f"{p}/alive/demonstrator/{ident}"]
        learners = [f"{p}/alive/learner/*"]
        out[f"demonstrator-{ident}"] = (
            ident,
            [
                _rule(f"demonstrator-{ident}-publish", ["put", "liveliness_token"], "ingress", own),
                _rule(
                    f"demonstrator-{ident}-follow",
                    ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"],
                    "ingress",
                    [f"{p}/acks/{source}", *learners],
                ),
                _rule(f"demonstrator-{ident}-receive", ["put"], "egress", [f"{p}/acks/{source}"]),
                _rule(f"demonstrator-{ident}-learners", ["liveliness_token", "reply"], "egress", learners),
            ],
        )
    for e in d.evaluators:
        own = [f"{p}/eval/{e}", f"{p}/alive/evaluator/{e}"]
        out[f"evaluator-{e}"] = (
            e,
            [
                _rule(f"evaluator-{e}-publish", ["put", "liveliness_token"], "ingress", own),
                _rule(
                    f"evaluator-{e}-follow", ["declare_subscriber", "query"], "ingress", [f"{p}/weights/*"]
                ),
                _rule(f"evaluator-{e}-receive", ["put", "reply"], "egress", [f"{p}/weights/*"]),
            ],
        )
    for o in d.operators:
        asks = [keys.everything(d.run, "status"), f"{p}/alive/**"]
        out[f"operator-{o}"] = (
            o,
            [
                _rule(
                    f"operator-{o}-ask",
                    ["query", "declare_liveliness_subscriber", "liveliness_query"],
                    "ingress",
                    asks,
                ),
                _rule(f"operator-{o}-answers", ["reply", "liveliness_token"], "egress", asks),
            ],
        )
    return out


def access_control(d: Deployment) -> dict:
    """The ``access_control`` section (deny by default) for deployment ``d``."""
    d.users()
    rules, subjects, policies = [], [], []
    for subject, (user, role_rules) in _role_rules(d).items():
        rules.extend(role_rules)
        entry = {"id": subject, "usernames": [user]}
        if d.cert_names:
            entry["cert_common_names"] = [user]
        subjects.append(entry)
        policies.append({"rules": [r["id"] for r in role_rules], "subjects": [subject]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def write_deployment(out: str | Path, d: Deployment) -> dict[str, Path]:
    """Write users.txt, one <user>.credentials per process (fresh random passwords) and acl.json5."""
    users = d.users()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    passwords = {user: secrets.token_urlsafe(24) for user in users}
    written = {"users.txt": out / "users.txt", "acl.json5": out / "acl.json5"}
    write_private(written["users.txt"], "".join(f"{u}:{pw}\n" for u, pw in passwords.items()))
    for user, password in passwords.items():
        written[f"{user}.credentials"] = out / f"{user}.credentials"
        write_private(written[f"{user}.credentials"], f"{user}:{password}\n")
    header = (
        f"// navlearn access control for run {d.run!r}: navlearn router --auth-dictionary users.txt "
        "--acl acl.json5\n"
    )
    body = json.dumps({"access_control": access_control(d)}, indent=2)
    written["acl.json5"].write_text(header + body + "\n")
    return written

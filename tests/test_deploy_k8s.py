"""deploy/k8s: the kustomization renders, and every piece is there and agrees with the others.

The secrets are made with the very commands written in kustomization.yaml's header
(``navlearn certs``, ``navlearn credentials``), in a copy of deploy/k8s. The manifests are
rendered with ``kubectl kustomize`` when kubectl is installed; without it that test is skipped
with the reason, and the same checks run on the YAML files read directly (the namespace,
replicas, images, labels and generators of kustomization.yaml applied by hand). Nothing here
talks to a cluster: whether the pods run on one is not tested (README: Kubernetes).
"""

from __future__ import annotations

import base64
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import yaml

from services.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
K8S = ROOT / "deploy" / "k8s"
CLI = [sys.executable, "-m", "services.cli"]
ROLES = {"navlearn-router": "router", "navlearn-learner": "learner", "navlearn-actor": "actor",
         "navlearn-evaluator": "evaluator"}  # fmt: skip
WORKLOADS = ("Deployment", "StatefulSet")


def header_commands() -> list[list[str]]:
    """The ``navlearn certs`` and ``navlearn credentials`` commands of kustomization.yaml's header."""
    lines = [line.removeprefix("#").strip() for line in (K8S / "kustomization.yaml").read_text().splitlines()]
    joined = re.sub(r"\\\s*\n", " ", "\n".join(line for line in lines if line))
    return [
        shlex.split(line.split("#")[0])
        for line in joined.splitlines()
        if line.startswith(("navlearn certs ", "navlearn credentials "))
    ]


@pytest.fixture(scope="module")
def k8s(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of deploy/k8s with its secrets made by the header's commands."""
    out = tmp_path_factory.mktemp("k8s") / "k8s"
    shutil.copytree(K8S, out, ignore=shutil.ignore_patterns("secrets"))
    commands = header_commands()
    assert [c[1] for c in commands] == ["certs", "credentials"], commands
    for command in commands:
        argv = [
            str(out / a.removeprefix("deploy/k8s/")) if a.startswith("deploy/k8s/") else a for a in command
        ]
        done = subprocess.run([*CLI, *argv[1:]], capture_output=True, text=True, timeout=120, cwd=ROOT)
        assert done.returncode == 0, done.stderr
    return out


def render_plain(directory: Path) -> list[dict]:
    """What kustomize makes of this kustomization, for the fields it uses (no name hashes)."""
    kustomization = yaml.safe_load((directory / "kustomization.yaml").read_text())
    docs = [d for r in kustomization["resources"] for d in yaml.safe_load_all((directory / r).read_text())]
    for generator in kustomization.get("configMapGenerator", []):
        data = dict(literal.split("=", 1) for literal in generator.get("literals", []))
        docs.append({"apiVersion": "v1", "kind": "ConfigMap", "metadata": {"name": generator["name"]},
                     "data": data})  # fmt: skip
    for generator in kustomization.get("secretGenerator", []):
        data = {
            Path(f).name: base64.b64encode((directory / f).read_bytes()).decode() for f in generator["files"]
        }
        docs.append({"apiVersion": "v1", "kind": "Secret", "type": "Opaque",
                     "metadata": {"name": generator["name"]}, "data": data})  # fmt: skip
    replicas = {r["name"]: r["count"] for r in kustomization.get("replicas", [])}
    images = {
        i["name"]: f"{i.get('newName', i['name'])}:{i['newTag']}" for i in kustomization.get("images", [])
    }
    for doc in docs:
        meta = doc["metadata"]
        if doc["kind"] != "Namespace":
            meta["namespace"] = kustomization["namespace"]
        for pairs in kustomization.get("labels", []):
            meta.setdefault("labels", {}).update(pairs["pairs"])
            if pairs.get("includeTemplates") and doc["kind"] in WORKLOADS:
                doc["spec"]["template"]["metadata"]["labels"].update(pairs["pairs"])
        if doc["kind"] in WORKLOADS:
            doc["spec"]["replicas"] = replicas.get(meta["name"], doc["spec"].get("replicas", 1))
            for container in doc["spec"]["template"]["spec"]["containers"]:
                container["image"] = images.get(container["image"], container["image"])
    return docs


def render_kubectl(directory: Path) -> list[dict]:
    done = subprocess.run(
        ["kubectl", "kustomize", str(directory)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    return [d for d in yaml.safe_load_all(done.stdout) if d]


def endpoint_port(endpoint: str) -> tuple[str, str, int]:
    proto, _, address = endpoint.partition("/")
    host, _, port = address.rpartition(":")
    return proto, host, int(port)


def check_manifests(docs: list[dict], k8s: Path) -> None:
    """Every piece there, and consistent: names, ports, run name, secrets mounted, certificates."""
    from cryptography import x509

    by = {(d["kind"], d["metadata"]["name"]): d for d in docs}

    def find(kind: str, name: str) -> dict:  # kustomize appends a content hash to generated names
        hits = [d for (k, n), d in by.items() if k == kind and (n == name or n.rsplit("-", 1)[0] == name)]
        assert len(hits) == 1, f"{kind} {name}: {sorted(by)}"
        return hits[0]

    kustomization = yaml.safe_load((k8s / "kustomization.yaml").read_text())
    namespace = kustomization["namespace"]
    assert find("Namespace", namespace)
    assert {d["metadata"].get("namespace") for d in docs if d["kind"] != "Namespace"} == {namespace}
    workloads = {
        "navlearn-router": find("Deployment", "navlearn-router"),
        "navlearn-learner": find("StatefulSet", "navlearn-learner"),
        "navlearn-actor": find("Deployment", "navlearn-actor"),
        "navlearn-evaluator": find("Deployment", "navlearn-evaluator"),
    }
    service, zenoh_env = find("Service", "navlearn-router"), find("ConfigMap", "navlearn-zenoh")["data"]
    secrets = {n: find("Secret", n) for n in ("navlearn-tls", "navlearn-credentials")}
    files = {  # generated name -> {key: bytes}
        s["metadata"]["name"]: {k: base64.b64decode(v) for k, v in s["data"].items()}
        for s in secrets.values()
    }
    parser = build_parser()
    images = set()
    for name, workload in workloads.items():
        spec, pod = workload["spec"], workload["spec"]["template"]
        labels = pod["metadata"]["labels"]
        assert spec["selector"]["matchLabels"].items() <= labels.items(), name
        assert labels.get("app.kubernetes.io/part-of") == "navlearn", name  # what the NetworkPolicy admits
        (container,) = pod["spec"]["containers"]
        images.add(container["image"])
        env = {}
        for source in container.get("envFrom", []):
            assert source["configMapRef"]["name"] == find("ConfigMap", "navlearn-zenoh")["metadata"]["name"]
            env.update(zenoh_env)
        env.update({e["name"]: e.get("value") for e in container.get("env", [])})
        argv = [re.sub(r"\$\((\w+)\)", "pod-name-0", a) for a in container["args"]]
        args = parser.parse_args(argv)  # every flag is a real navlearn flag (SystemExit otherwise)
        assert args.command == ROLES[name], (name, argv)
        # every file a container names is mounted from a secret holding it
        volumes = {v["name"]: v for v in pod["spec"]["volumes"]}
        volumes.update({c["metadata"]["name"]: {"claim": c} for c in spec.get("volumeClaimTemplates", [])})
        mounts = {m["mountPath"]: volumes[m["name"]] for m in container["volumeMounts"]}
        paths = [v for v in env.values() if v and v.startswith("/etc/")]
        paths += [a.split("=", 1)[1] for a in argv if "=" in a and a.split("=", 1)[1].startswith("/etc/")]
        for path in paths:
            directory, key = path.rsplit("/", 1)
            assert directory in mounts, f"{name}: {path} is not under a mounted volume"
            secret = mounts[directory].get("secret", {})
            items = [i["key"] for i in secret.get("items", [])] or list(files[secret["secretName"]])
            assert key in items and key in files[secret["secretName"]], f"{name}: {path} not in the secret"
        if name == "navlearn-router":
            (listen,) = args.zenoh_listen
            proto, host, port = endpoint_port(listen)
            assert (proto, host) == ("tls", "0.0.0.0") and args.zenoh_tls_mtls and args.zenoh_auth_dictionary
            (container_port,) = container["ports"]
            assert container_port["containerPort"] == port
            (service_port,) = service["spec"]["ports"]
            assert service_port["targetPort"] in (port, container_port["name"])
            assert service["spec"]["selector"].items() <= labels.items()
            router_port, router_labels = service_port["port"], labels
            users = dict(
                line.split(":", 1) for line in files[secrets["navlearn-credentials"]["metadata"]["name"]]
                ["users.txt"].decode().splitlines() if line.strip()
            )  # fmt: skip
            continue
        # clients: the same run from the ConfigMap, mutual TLS with their own pair, a known user
        assert "NAVLEARN_RUN" in env and "--run" not in " ".join(argv), name
        assert env["NAVLEARN_TLS_MTLS"] == "1" and env["NAVLEARN_TLS_CERT"] and env["NAVLEARN_TLS_KEY"], name
        credentials = files[mounts["/etc/navlearn/credentials"]["secret"]["secretName"]]
        user, _, password = (
            credentials[env["NAVLEARN_ZENOH_CREDENTIALS"].rsplit("/", 1)[1]].decode().strip().partition(":")
        )
        assert users.get(user) == password, f"{name}: its credentials are not in the router's users.txt"
        if name in ("navlearn-learner", "navlearn-evaluator"):
            assert args.opt_id == user, f"{name}: --id {args.opt_id} is not its Zenoh user {user}"
    assert len(images) == 1, images
    proto, host, port = endpoint_port(zenoh_env["NAVLEARN_CONNECT"])
    assert (proto, host, port) == ("tls", service["metadata"]["name"], router_port)
    # the router's certificate names the Service, as clients verify it; clients' are the CA's
    tls = files[secrets["navlearn-tls"]["metadata"]["name"]]
    server = x509.load_pem_x509_certificate(tls["server.pem"])
    names = server.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert {host, f"{host}.{namespace}.svc"} <= set(names.get_values_for_type(x509.DNSName))
    ca = x509.load_pem_x509_certificate(tls["ca.pem"])
    assert all(x509.load_pem_x509_certificate(tls[k]).issuer == ca.subject for k in tls if k.endswith(".pem"))
    # the run the credentials were made for is the run every client joins
    (credentials_command,) = [c for c in header_commands() if c[1] == "credentials"]
    assert credentials_command[credentials_command.index("--run") + 1] == zenoh_env["NAVLEARN_RUN"]
    # learner: its volume holds the checkpoints; liveness and startup from navlearn status
    learner = workloads["navlearn-learner"]["spec"]
    (claim,) = learner["volumeClaimTemplates"]
    (container,) = learner["template"]["spec"]["containers"]
    (data_mount,) = [m for m in container["volumeMounts"] if m["name"] == claim["metadata"]["name"]]
    checkpoint_dir = parser.parse_args(container["args"]).opt_checkpoint_dir
    assert checkpoint_dir.startswith(data_mount["mountPath"] + "/"), checkpoint_dir
    for probe in ("livenessProbe", "startupProbe"):
        command = container[probe]["exec"]["command"]
        assert command[:2] == ["navlearn", "status"] and parser.parse_args(command[1:]).command == "status"
    assert learner["replicas"] == 1
    # actors: the replica count is the number of actors
    actors = workloads["navlearn-actor"]["spec"]["replicas"]
    assert actors == {r["name"]: r["count"] for r in kustomization["replicas"]}["navlearn-actor"] >= 1
    # only navlearn's pods reach the router's port
    policy = find("NetworkPolicy", "navlearn-router")["spec"]
    assert policy["podSelector"]["matchLabels"].items() <= router_labels.items()
    (rule,) = policy["ingress"]
    assert [p["port"] for p in rule["ports"]] == [router_port]
    assert rule["from"][0]["podSelector"]["matchLabels"] == {"app.kubernetes.io/part-of": "navlearn"}


def test_kubectl_kustomize_renders_consistent_manifests(k8s: Path) -> None:
    if shutil.which("kubectl") is None:
        pytest.skip("kubectl is not installed (test_manifests_parsed_directly checks the files without it)")
    check_manifests(render_kubectl(k8s), k8s)


def test_manifests_parsed_directly_are_consistent(k8s: Path) -> None:
    check_manifests(render_plain(k8s), k8s)


def test_container_image_installs_the_project() -> None:
    """The Dockerfile copies every package pyproject.toml installs, installs it, runs the CLI."""
    text = (K8S / "Dockerfile").read_text()
    packages = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]["find"]
    for pattern in packages["include"]:
        assert re.search(rf"^COPY {pattern.rstrip('*')} ", text, re.M), pattern
    assert re.search(r"^RUN python -m pip install \. ", text, re.M)
    assert "download.pytorch.org/whl/cpu" in text  # CPU-only torch
    assert re.search(r'^ENTRYPOINT \["navlearn"\]', text, re.M)
    pinned = [d for d in tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
              if d.startswith("torch==")]  # fmt: skip
    assert pinned and f"pip install {pinned[0]} " in text, "the image's torch is not pyproject's pin"

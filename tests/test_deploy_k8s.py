"""deploy/k8s: `kubectl kustomize` renders every piece, and the pieces agree with each other and the CLI.

Rendered only (nothing is applied to a cluster): the router Service and Deployment, the learner
StatefulSet with its volume, the actor Deployment (replicas = actors), the evaluator, the
Secrets; ports, run name, every certificate and credentials path mounted from a Secret key
that exists, every container's arguments accepted by the real `navlearn` parser.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from services.cli import build_parser

K8S = Path(__file__).resolve().parents[1] / "deploy" / "k8s"
KUBECTL = shutil.which("kubectl")
pytestmark = pytest.mark.skipif(KUBECTL is None, reason="kubectl is not installed: cannot render deploy/k8s")


@pytest.fixture(scope="module")
def rendered() -> dict[tuple[str, str], dict]:
    out = subprocess.run(
        [KUBECTL, "kustomize", str(K8S)], capture_output=True, text=True, timeout=60, check=True
    ).stdout
    docs = [doc for doc in yaml.safe_load_all(out) if doc]
    return {(doc["kind"], doc["metadata"]["name"]): doc for doc in docs}


def workloads(rendered) -> dict[str, dict]:
    return {name: doc for (kind, name), doc in rendered.items() if kind in ("Deployment", "StatefulSet")}


def container(doc: dict) -> dict:
    (only,) = doc["spec"]["template"]["spec"]["containers"]
    return only


def env_of(doc: dict, rendered) -> dict[str, str]:
    """The container's environment: its ConfigMaps (envFrom), then its own env entries."""
    spec = container(doc)
    env: dict[str, str] = {}
    for source in spec.get("envFrom", []):
        env.update(rendered[("ConfigMap", source["configMapRef"]["name"])]["data"])
    env.update({e["name"]: e.get("value", "") for e in spec.get("env", []) if "value" in e})
    return env


def mounted_files(doc: dict, rendered) -> set[str]:
    """Paths of the files the pod's Secret volumes put in the container."""
    pod = doc["spec"]["template"]["spec"]
    volumes = {v["name"]: v for v in pod.get("volumes", [])}
    files = set()
    for mount in container(doc).get("volumeMounts", []):
        secret = volumes.get(mount["name"], {}).get("secret")
        if secret is None:
            continue
        data = rendered[("Secret", secret["secretName"])]
        keys = set(data.get("stringData", {})) | set(data.get("data", {}))
        items = secret.get("items") or [{"key": k, "path": k} for k in keys]
        for item in items:
            assert item["key"] in keys, f"{secret['secretName']} has no key {item['key']}"
            files.add(f"{mount['mountPath']}/{item['path']}")
    return files


def test_every_piece_is_there(rendered):
    kinds = {(kind, name) for kind, name in rendered}
    for piece in [
        ("Namespace", "navlearn"),
        ("Service", "navlearn-router"),
        ("Deployment", "navlearn-router"),
        ("StatefulSet", "navlearn-learner"),
        ("Deployment", "navlearn-actor"),
        ("Deployment", "navlearn-evaluator"),
        ("Secret", "navlearn-tls"),
        ("Secret", "navlearn-credentials"),
    ]:
        assert piece in kinds
    assert any(kind == "ConfigMap" and name.startswith("navlearn-env") for kind, name in kinds)
    for (kind, name), doc in rendered.items():
        if kind != "Namespace":
            assert doc["metadata"]["namespace"] == "navlearn", (kind, name)
    assert workloads(rendered)["navlearn-actor"]["spec"]["replicas"] == 2  # kustomization's count


def test_ports_run_and_endpoints_agree(rendered):
    service = rendered[("Service", "navlearn-router")]
    router = workloads(rendered)["navlearn-router"]
    (port,) = service["spec"]["ports"]
    (container_port,) = container(router)["ports"]
    assert port["targetPort"] == container_port["name"]
    assert service["spec"]["selector"].items() <= router["spec"]["template"]["metadata"]["labels"].items()
    assert env_of(router, rendered)["NAVLEARN_LISTEN"].endswith(f":{container_port['containerPort']}")
    for name, doc in workloads(rendered).items():
        if name == "navlearn-router":
            continue
        env = env_of(doc, rendered)
        assert env["NAVLEARN_CONNECT"] == f"tls/{service['metadata']['name']}:{port['port']}", name
        assert env["NAVLEARN_RUN"] == "main", name


def test_certificates_and_credentials_are_mounted(rendered):
    for name, doc in workloads(rendered).items():
        env, files = env_of(doc, rendered), mounted_files(doc, rendered)
        wanted = [
            value
            for key, value in env.items()
            if key.startswith("NAVLEARN_TLS_")
            or key in ("NAVLEARN_ZENOH_CREDENTIALS", "NAVLEARN_ZENOH_AUTH_DICTIONARY")
        ]
        assert wanted, name
        for path in wanted:
            assert path in files, f"{name}: {path} is not mounted from a Secret"
        probe = container(doc).get("livenessProbe", {}).get("exec", {}).get("command", [])
        for arg in probe:
            if arg.startswith("--credentials="):
                assert arg.split("=", 1)[1] in files, name


def test_learner_state_on_its_volume_and_liveness_from_status(rendered):
    learner = workloads(rendered)["navlearn-learner"]
    (claim,) = learner["spec"]["volumeClaimTemplates"]
    mount = next(m for m in container(learner)["volumeMounts"] if m["name"] == claim["metadata"]["name"])
    args = container(learner)["args"]
    checkpoint_dir = next(a.split("=", 1)[1] for a in args if a.startswith("--checkpoint-dir="))
    assert checkpoint_dir.startswith(mount["mountPath"] + "/")
    assert "--replay-storage=memmap" in args
    assert container(learner)["livenessProbe"]["exec"]["command"][:2] == ["navlearn", "status"]
    assert learner["spec"]["template"]["spec"]["terminationGracePeriodSeconds"] >= 120


def test_container_arguments_parse(rendered):
    parser = build_parser()
    for name, doc in workloads(rendered).items():
        spec = container(doc)
        assert spec["image"].startswith("navlearn:"), name
        args = [a.replace("$(POD_NAME)", "navlearn-actor-0") for a in spec["args"]]
        parsed = parser.parse_args(args)  # exits (SystemExit) on an unknown flag or command
        assert parsed.command == args[0]
        probe = spec.get("livenessProbe", {}).get("exec", {}).get("command")
        if probe:
            assert parser.parse_args(probe[1:]).command == "status"

"""Zenoh session settings from flags, environment and files (no network here)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from services.cli import build_parser
from services.common.transport import (
    DEFAULT_ENDPOINT,
    TransportError,
    ZenohSettings,
    add_zenoh_args,
    build_config,
    read_credentials,
    settings_from_args,
)

DEPLOY = Path(__file__).resolve().parents[1] / "deploy"
ENV_VARS = [
    "NAVLEARN_ZENOH_MODE", "NAVLEARN_CONNECT", "NAVLEARN_LISTEN", "NAVLEARN_RUN", "NAVLEARN_ZENOH_CONFIG",
    "NAVLEARN_ZENOH_MULTICAST", "NAVLEARN_TLS_ROOT_CA", "NAVLEARN_TLS_CERT", "NAVLEARN_TLS_KEY",
    "NAVLEARN_TLS_MTLS", "NAVLEARN_ZENOH_CREDENTIALS", "NAVLEARN_ZENOH_USER", "NAVLEARN_ZENOH_PASSWORD",
    "NAVLEARN_ZENOH_AUTH_DICTIONARY", "NAVLEARN_ZENOH_ACL", "NAVLEARN_CONNECT_TIMEOUT",
]  # fmt: skip


@pytest.fixture(autouse=True)
def clean_env(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ENV_VARS:
        monkeypatch.delenv(name, raising=False)


def parse(argv: list[str], **kw) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_zenoh_args(parser, **kw)
    return parser.parse_args(argv)


def get(conf, key: str):
    return json.loads(conf.get_json(key))


def test_defaults_make_a_client_of_the_local_router_without_multicast() -> None:
    settings = settings_from_args(parse([]))
    assert (settings.mode, settings.run, settings.connect) == ("client", "default", None)
    conf = build_config(settings)
    assert get(conf, "mode") == "client"
    assert get(conf, "connect/endpoints") == [DEFAULT_ENDPOINT]
    assert get(conf, "scouting/multicast/enabled") is False


def test_router_mode_listens_on_the_default_endpoint() -> None:
    conf = build_config(settings_from_args(parse([], default_mode="router")))
    assert get(conf, "mode") == "router"
    assert get(conf, "listen/endpoints") == [DEFAULT_ENDPOINT]
    assert get(conf, "connect/endpoints") == []


def test_flags_beat_environment_variables(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("NAVLEARN_CONNECT", "tcp/10.0.0.1:7447, tcp/10.0.0.2:7447")
    monkeypatch.setenv("NAVLEARN_RUN", "exp7")
    monkeypatch.setenv("NAVLEARN_ZENOH_MULTICAST", "1")
    monkeypatch.setenv("NAVLEARN_CONNECT_TIMEOUT", "2.5")
    from_env = settings_from_args(parse([]))
    assert from_env.connect == ["tcp/10.0.0.1:7447", "tcp/10.0.0.2:7447"] and from_env.run == "exp7"
    assert from_env.multicast_scouting is True and from_env.connect_timeout == 2.5
    flags = settings_from_args(parse(["--connect", "tcp/192.0.2.7:1", "--run", "exp8", "--mode", "peer"]))
    assert (flags.connect, flags.run, flags.mode) == (["tcp/192.0.2.7:1"], "exp8", "peer")
    assert get(build_config(from_env), "scouting/multicast/enabled") is True


def test_a_config_file_is_kept_where_no_flag_overrides_it(tmp_path: Path) -> None:
    file = tmp_path / "z.json5"
    file.write_text(
        '{ mode: "peer", connect: { endpoints: ["tcp/192.0.2.1:7447"] },'
        " scouting: { multicast: { enabled: true } } }"
    )
    conf = build_config(settings_from_args(parse(["--zenoh-config", str(file)])))
    assert get(conf, "mode") == "peer" and get(conf, "connect/endpoints") == ["tcp/192.0.2.1:7447"]
    assert get(conf, "scouting/multicast/enabled") is True
    conf = build_config(
        settings_from_args(
            parse(["--zenoh-config", str(file), "--mode", "client", "--connect", "tcp/192.0.2.7:1"])
        )
    )
    assert get(conf, "mode") == "client" and get(conf, "connect/endpoints") == ["tcp/192.0.2.7:1"]


def test_bad_values_are_one_clear_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(TransportError, match="run"):
        settings_from_args(parse(["--run", "a/b"]))
    monkeypatch.setenv("NAVLEARN_ZENOH_MODE", "server")
    with pytest.raises(TransportError, match="mode"):
        settings_from_args(parse([]))
    with pytest.raises(TransportError, match="does not exist"):
        build_config(ZenohSettings(tls_root_ca=str(tmp_path / "missing.pem")))
    with pytest.raises(TransportError, match="go together"):
        build_config(ZenohSettings(tls_cert=str(tmp_path / "c.pem")))
    with pytest.raises(TransportError, match="'carrier-pigeon' has no protocol: write it as tcp/"):
        build_config(ZenohSettings(connect=["carrier-pigeon"]))
    (tmp_path / "x.json5").write_text("{}")
    with pytest.raises(TransportError, match="mutual TLS"):
        build_config(
            ZenohSettings(
                tls_mtls=True, tls_cert=str(tmp_path / "x.json5"), tls_key=str(tmp_path / "x.json5")
            )
        )
    with pytest.raises(TransportError, match="access_control"):
        build_config(ZenohSettings(mode="router", acl_file=str(tmp_path / "x.json5")))


def test_credentials_come_from_a_file_or_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert read_credentials(ZenohSettings()) is None
    file = tmp_path / "actor.credentials"
    file.write_text("# navlearn actor\nactor:s3cret:with:colons\n")
    settings = ZenohSettings(credentials_file=str(file))
    assert read_credentials(settings) == ("actor", "s3cret:with:colons")
    conf = build_config(settings)
    assert get(conf, "transport/auth/usrpwd/user") == "actor"
    monkeypatch.setenv("NAVLEARN_ZENOH_USER", "learner")
    with pytest.raises(TransportError, match="both"):
        read_credentials(ZenohSettings())
    monkeypatch.setenv("NAVLEARN_ZENOH_PASSWORD", "pw")
    assert read_credentials(ZenohSettings()) == ("learner", "pw")
    file.write_text("no-colon-here\n")
    with pytest.raises(TransportError, match="user:password"):
        read_credentials(settings)


def test_no_flag_takes_a_password() -> None:
    help_text = build_parser()._subparsers._group_actions[0].choices["router"].format_help()
    assert "--credentials" in help_text and "--password" not in help_text and "--user" not in help_text


def test_tls_and_acl_settings_reach_the_config(tmp_path: Path) -> None:
    for name in ("ca.pem", "cert.pem", "key.pem"):
        (tmp_path / name).write_text("x")
    settings = ZenohSettings(
        mode="router",
        tls_root_ca=str(tmp_path / "ca.pem"),
        tls_cert=str(tmp_path / "cert.pem"),
        tls_key=str(tmp_path / "key.pem"),
        tls_mtls=True,
        acl_file=str(DEPLOY / "router-secure.json5"),
    )
    conf = build_config(settings)
    tls = get(conf, "transport/link/tls")
    assert tls["root_ca_certificate"].endswith("ca.pem") and tls["enable_mtls"] is True
    assert tls["listen_certificate"] == tls["connect_certificate"] == str(tmp_path / "cert.pem")
    acl = get(conf, "access_control")
    assert acl["enabled"] and acl["default_permission"] == "deny" and len(acl["policies"]) == 7


@pytest.mark.parametrize("name", ["router.json5", "router-secure.json5"])
def test_deploy_router_configs_are_valid_zenoh_configs(name: str) -> None:
    conf = build_config(ZenohSettings(mode=None, config_file=str(DEPLOY / name)))
    assert get(conf, "mode") == "router" and get(conf, "scouting/multicast/enabled") is False


def test_router_command_has_no_mode_or_run_flags() -> None:
    args = build_parser().parse_args(["router", "--listen", "tcp/127.0.0.1:1"])
    settings = settings_from_args(args, mode="router")
    assert settings.mode == "router" and settings.listen == ["tcp/127.0.0.1:1"]
    with pytest.raises(SystemExit):
        build_parser().parse_args(["router", "--mode", "client"])

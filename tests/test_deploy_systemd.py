"""The systemd units' commands are ones `navlearn` accepts (systemd itself is not run here): every
ExecStart's flags parse, the unit reads navlearn.env, and the demonstrator's settings there are
variables its command reads."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from services.cli import build_parser
from services.demonstrator.config import DemonstratorConfig
from services.learner.config import LearnerConfig

UNITS = Path(__file__).resolve().parents[1] / "deploy" / "systemd"


def exec_start(unit: Path) -> list[str]:
    text = unit.read_text().replace("\\\n", " ")
    line = next(x for x in text.splitlines() if x.startswith("ExecStart="))
    line = line.removeprefix("ExecStart=").replace("${NAVLEARN_ROUTER}", "tcp/127.0.0.1:7447")
    line = line.replace("${NAVLEARN_ROBOT_ROUTER}", "tcp/127.0.0.1:7447")
    return shlex.split(line.replace("%H", "host").replace("%i", "1"))


@pytest.mark.parametrize("unit", sorted(UNITS.glob("*.service")), ids=lambda p: p.name)
def test_every_unit_command_parses(unit):
    argv = exec_start(unit)
    assert argv[0].endswith("/navlearn")
    args = build_parser().parse_args(argv[1:])  # exits (SystemExit) on an unknown flag
    assert callable(args.func)
    assert "EnvironmentFile=/etc/navlearn/navlearn.env" in unit.read_text()


def test_nirl_settings_in_navlearn_env_are_ones_the_services_read():
    env = (UNITS / "navlearn.env").read_text()
    names = set(re.findall(r"^#? ?(NAVLEARN_[A-Z_]+)=", env, re.MULTILINE))
    assert {"NAVLEARN_LEARNER_NIRL", "NAVLEARN_DEMONSTRATOR_SOURCE", "NAVLEARN_EVALUATOR_COMPARE"} <= names
    fields = {
        "NAVLEARN_LEARNER_": set(LearnerConfig.__dataclass_fields__),
        "NAVLEARN_DEMONSTRATOR_": set(DemonstratorConfig.__dataclass_fields__),
    }
    for name in names:
        for prefix, known in fields.items():
            if name.startswith(prefix):
                assert name.removeprefix(prefix).lower() in known, name


def test_drive_settings_in_navlearn_env_are_ones_the_drive_reads():
    """navlearn-drive.service: its NAVLEARN_DRIVE_* examples are fields of DriveConfig, and the unit
    stops it with SIGTERM (the drive sends zero velocity first)."""
    from services.drive.config import DriveConfig

    env = (UNITS / "navlearn.env").read_text()
    names = set(re.findall(r"^#? ?(NAVLEARN_DRIVE_[A-Z_]+)=", env, re.MULTILINE))
    assert "NAVLEARN_DRIVE_POLICY" in names and "NAVLEARN_ROBOT_ROUTER" in env
    for name in names:
        assert name.removeprefix("NAVLEARN_DRIVE_").lower() in DriveConfig.__dataclass_fields__, name
    assert "KillSignal=SIGTERM" in (UNITS / "navlearn-drive.service").read_text()


def test_supervisord_drive_program_parses():
    """deploy/supervisord.conf's [program:drive]: supervisord reads it, and its command line is one
    navlearn drive accepts."""
    import configparser

    conf = configparser.RawConfigParser(strict=False)
    conf.read(UNITS.parent / "supervisord.conf")
    command = conf.get("program:drive", "command")
    inner = shlex.split(shlex.split(command)[2].removeprefix("exec ").replace("${NAVLEARN_ROBOT_ROUTER:-", "")
                        .replace("}", ""))  # fmt: skip
    args = build_parser().parse_args(inner[1:])
    assert inner[0] == "navlearn" and args.command == "drive" and args.zenoh_connect == ["tcp/127.0.0.1:7447"]
    assert (
        conf.get("program:drive", "autostart") == "false"
        and conf.get("program:drive", "stopsignal") == "TERM"
    )

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

"""The command line: demos generate/info, imitate train, evaluate - in-process, tiny sizes."""

from __future__ import annotations

import json

from services.cli import main


def test_demos_imitate_evaluate_pipeline(tmp_path, capsys):
    demos = tmp_path / "expert-v0"
    assert main(["demos", "generate", "--maps", "rooms:12", "--episodes", "6", "--noise", "0.2",
                 "--out", str(demos)]) == 0  # fmt: skip
    assert main(["demos", "info", str(demos)]) == 0
    assert "episodes" in capsys.readouterr().out
    policy = tmp_path / "policy"
    assert main(["imitate", "train", "--demos", str(demos), "--out", str(policy), "--max-epochs", "3",
                 "--hidden-sizes", "16", "16"]) == 0  # fmt: skip
    config = json.loads((policy / "config.json").read_text())
    assert config["kind"] == "policy_logits" and config["architecture"]["hidden_sizes"] == [16, 16]
    assert len((policy / "training.jsonl").read_text().splitlines()) == config["training"]["epochs"]
    out = tmp_path / "eval"
    assert main(["evaluate", "--policy", str(policy), "--maps", "unseen", "movingai", "--episodes", "3",
                 "--out", str(out)]) == 0  # fmt: skip
    report = json.loads((out / "eval.json").read_text())
    assert set(report["metrics"]) == {"unseen", "movingai"}
    assert (out / "paths_unseen.png").stat().st_size > 0 and (out / "paths_movingai.png").exists()
    assert "success" in capsys.readouterr().out


def test_bad_inputs_exit_with_code_2(tmp_path, capsys):
    assert main(["demos", "generate", "--maps", "nowhere:12", "--out", str(tmp_path / "d-v0")]) == 2
    assert main(["demos", "generate", "--out", str(tmp_path / "no_version")]) == 2
    assert main(["demos", "info", str(tmp_path / "missing-v0")]) == 2
    assert (
        main(["imitate", "train", "--demos", str(tmp_path / "missing-v0"), "--out", str(tmp_path / "p")]) == 2
    )
    assert main(["evaluate", "--policy", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 5  # one clear line each

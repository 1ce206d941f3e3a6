"""Command-line tools: every ``[project.scripts]`` entry is a function of ``atrv_warp.cli`` that answers ``--help``, and
``atrv-baseline`` is ``evaluate --baseline``."""

from __future__ import annotations

import importlib
import json
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_every_console_script_points_into_cli_or_deploy_and_answers_help(capsys):
    """Every ``[project.scripts]`` entry is a function in ``atrv_warp.cli`` (or the robot-side ``atrv_warp.deploy``)
    that answers ``--help``."""
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert {"atrv-train", "atrv-evaluate", "atrv-baseline"} <= scripts.keys()
    assert scripts["atrv-baseline"] == "atrv_warp.cli.evaluate:baseline_main"
    assert scripts["atrv-deploy"] == "atrv_warp.deploy:main"  # the robot-side package ships its own command
    for script, target in scripts.items():
        module, _, func = target.partition(":")
        assert module.startswith("atrv_warp.cli.") or module == "atrv_warp.deploy", script
        main = getattr(importlib.import_module(module), func)
        assert callable(main), script
        argv = [script, "--help"] if module.endswith(".ros") else ["--help"]  # the ROS tools take rclpy's argv
        try:
            code = main(argv)
        except SystemExit as stop:  # argparse's --help
            code = stop.code
        assert code in (0, None), script
        assert capsys.readouterr().out.strip(), f"{script} --help printed nothing"


def test_atrv_baseline_is_evaluate_baseline(tmp_path, capsys):
    from atrv_warp.cli.evaluate import baseline_main, main

    assert baseline_main(["--episodes", "4", "--json", str(tmp_path / "a.json")]) == 0
    assert main(["--baseline", "--episodes", "4", "--json", str(tmp_path / "b.json")]) == 0
    a, b = (json.loads((tmp_path / f"{n}.json").read_text()) for n in "ab")
    assert a == b and a["episodes"] == 4 and a["policy"] == "scripted baseline (reach)"
    printed = capsys.readouterr().out
    # every end the help names, obstacles among them even at 0, and that the physics was nominal
    assert "scripted baseline (reach)" in printed and " obstacle 0.0% " in printed and printed.rstrip().endswith(
        "| nominal")


def test_evaluate_under_randomization_reports_success_by_bin(tmp_path, capsys):
    from atrv_warp.cli.evaluate import main

    out = tmp_path / "wide.json"
    assert main(["--task", "nav", "--randomization", "wide", "--episodes", "16", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["randomization"] == "wide" and result["episodes"] == 16
    bins = result["success_by_bin"]
    assert set(bins) == {"friction", "payload_mass", "latency"}
    assert all(sum(r["episodes"] for r in rows) == 16 for rows in bins.values())
    printed = capsys.readouterr().out
    assert "randomization wide" in printed and "success by friction" in printed
    assert main(["--task", "nav", "--randomization", "wild", "--episodes", "2"]) == 2
    assert "unknown randomization preset 'wild'" in capsys.readouterr().err


def test_a_policy_for_another_version_of_the_task_is_refused_by_name(tmp_path, capsys):
    """A nav policy saved before the nav task observed its last actions (26 values, not 32): one line naming
    the file and both sizes, exit 2, nothing run."""
    from atrv_warp.cli.evaluate import main
    from atrv_warp.policy import load_policy, make_actor, save_policy
    from atrv_warp.storage import FileFormatError

    old = tmp_path / "old_nav.pt"
    save_policy(make_actor(16, 1, obs_dim=26), old, width=16, depth=1, meta={"task": "nav"})
    assert main([str(old), "--episodes", "2"]) == 2
    err = capsys.readouterr().err
    assert str(old) in err and "observes 26 values, task 'nav' observes 32" in err and len(err.splitlines()) == 1
    with pytest.raises(FileFormatError, match="train it again"):
        load_policy(old, task="nav")
    load_policy(old)  # without a task to check against, it loads

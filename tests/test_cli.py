"""Command-line tools: every ``[project.scripts]`` entry resolves to a function, and
``atrv-baseline`` is ``evaluate --baseline``."""

from __future__ import annotations

import importlib
import json
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_every_script_entry_point_resolves():
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert {"atrv-train", "atrv-evaluate", "atrv-baseline"} <= scripts.keys()
    for name, target in scripts.items():
        module, _, func = target.partition(":")
        assert callable(getattr(importlib.import_module(module), func)), name
    assert scripts["atrv-baseline"] == "atrv_warp.evaluate:baseline_main"


def test_atrv_baseline_is_evaluate_baseline(tmp_path, capsys):
    from atrv_warp.evaluate import baseline_main, main

    assert baseline_main(["--episodes", "4", "--json", str(tmp_path / "a.json")]) == 0
    assert main(["--baseline", "--episodes", "4", "--json", str(tmp_path / "b.json")]) == 0
    a, b = (json.loads((tmp_path / f"{n}.json").read_text()) for n in "ab")
    assert a == b and a["episodes"] == 4 and a["policy"] == "scripted baseline (reach)"
    assert "scripted baseline (reach)" in capsys.readouterr().out


def test_evaluate_under_randomization_reports_success_by_bin(tmp_path, capsys):
    from atrv_warp.evaluate import main

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

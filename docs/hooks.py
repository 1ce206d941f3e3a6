"""mkdocs hook: tables drawn from ``benchmarks/results/*.json`` at build time, so a measured figure
lives in its results file alone.

A page writes ``{{ results_table NAME }}`` on a line of its own; :data:`TABLES` maps ``NAME`` to the
function that reads the file and returns the Markdown table. An unknown name or a missing file
fails the build (mkdocs.yml: ``hooks: [docs/hooks.py]``).
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path

RESULTS = Path(__file__).resolve().parent.parent / "benchmarks" / "results"
PLACEHOLDER = re.compile(r"^\{\{ results_table (\w+) \}\}$", re.MULTILINE)


def _load(name: str) -> dict:
    return json.loads((RESULTS / name).read_text())


def _table(header: list[str], align: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(align) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def sim_throughput() -> str:
    """``sim_throughput.json``: env-steps/s and ms per step against the number of worlds."""
    rows = _load("sim_throughput.json")["rows"]
    return _table(["worlds", "env-steps/s", "ms/step"], ["---:"] * 3,
                  [[str(r["num_worlds"]), f"{r['env_steps_per_s']:,.0f}", f"{r['ms_per_step']:.3f}"] for r in rows])


def sim_choices() -> str:
    """``sim_throughput.json``: graph replay and tile GEMM on and off."""
    rows = _load("sim_throughput.json")["choices"]
    on = {True: "on", False: "off"}
    return _table(["worlds", "graph replay", "tile GEMM", "env-steps/s"], ["---:", "---", "---", "---:"],
                  [[str(r["num_worlds"]), on[r["use_graph"]], on[r["use_tile_gemm"]], f"{r['env_steps_per_s']:,.0f}"]
                   for r in rows])


def sim_vs_mujoco() -> str:
    """``sim_vs_mujoco.json``: our env-steps/s against MuJoCo's rollout of the twin."""
    rows = _load("sim_vs_mujoco.json")["rows"]
    return _table(["N", "ours env-steps/s", "MuJoCo env-steps/s", "ours / MuJoCo"], ["---:"] * 4,
                  [[str(r["num_worlds"]), f"{r['ours_env_steps_per_s']:,.0f}", f"{r['mujoco_env_steps_per_s']:,.0f}",
                    f"{r['ratio_ours_over_mujoco']:.2f}"] for r in rows])


TABLES: dict[str, Callable[[], str]] = {
    "sim_throughput": sim_throughput,
    "sim_choices": sim_choices,
    "sim_vs_mujoco": sim_vs_mujoco,
}


def render(markdown: str) -> str:
    """``markdown`` with every placeholder replaced by its table."""

    def table(match: re.Match) -> str:
        name = match.group(1)
        if name not in TABLES:
            raise KeyError(f"unknown results table {name!r}; known: {sorted(TABLES)}")
        return TABLES[name]()

    return PLACEHOLDER.sub(table, markdown)


def on_page_markdown(markdown: str, **kwargs) -> str:
    return render(markdown)

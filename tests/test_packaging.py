"""Packaging: every import is declared in pyproject.toml, and an installed package carries its data.

A missing dependency (matplotlib, once) does not show on a machine where it happens to be
installed; reading the imports does. The check maps each imported top-level module to the
distributions that provide it (``importlib.metadata.packages_distributions``) and requires one of
them among the requirements the importing file may rely on.
"""

from __future__ import annotations

import ast
import importlib.metadata as md
import re
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# Files that may import what an optional extra brings (they check for it and say how to install it).
EXTRA_USERS = {
    "ros": ("atrv_warp/integrations/ros/", "atrv_warp/deploy/", "atrv_warp/core/ros_interfaces.py", "tests/test_ros.py", "tests/test_deploy.py", "tests/test_deploy_ros.py",
            "benchmarks/transfer/deploy_closed_loop.py", "benchmarks/transfer/deploy_tf_flood.py"),
    "test": ("tests/",),
    "browser": ("atrv_warp/integrations/browser.py", "docs/make_pictures.py"),
    "onnx": ("atrv_warp/rl/export.py",),
    "track": ("atrv_warp/integrations/tracking.py", "atrv_warp/integrations/video.py"),
    "tensorboard": ("atrv_warp/integrations/video.py",),
    "ray": ("atrv_warp/rl/collectors.py", "atrv_warp/rl/ray_collector.py", "tests/test_ray.py", "benchmarks/perf/ray_collection.py"),
    "mujoco": ("atrv_warp/integrations/mujoco/", "benchmarks/perf/sim_vs_mujoco.py", "benchmarks/perf/mujoco_twin/",
               "benchmarks/transfer/mujoco_agreement.py", "benchmarks/transfer/mujoco_transfer.py",
               "benchmarks/transfer/mujoco_turning_study.py", "benchmarks/transfer/mujoco_odometry.py",
               "benchmarks/robots/robot_policies.py",
               "tests/test_mujoco_twin.py"),
}
SCANNED = ("atrv_warp", "tests", "benchmarks", "examples", "docs")
LOCAL_ROOTS = ("benchmarks/", "docs/")
"""Folders whose scripts import each other by module name: a benchmark in ``benchmarks/<topic>/`` imports
``benchmarks/_common.py`` and its topic's siblings, and ``docs/hooks.py`` those and its own helpers."""


FROM_A_ROS_INSTALL = {"launch", "launch_ros"}
"""Modules that only a ROS 2 install provides (no package index has them): ``ros2 launch``'s, imported by the launch
files (``atrv_warp/deploy/launching.py``) when a ROS install runs them."""


def _name(requirement: str) -> str:
    return re.sub(r"[-_.]+", "-", re.match(r"\s*([A-Za-z0-9_][A-Za-z0-9._-]*)", requirement).group(1)).lower()


def declared(pyproject_text: str) -> tuple[set[str], dict[str, set[str]]]:
    """Normalised names of the core requirements and of each extra's."""
    project = tomllib.loads(pyproject_text)["project"]
    extras = {k: {_name(r) for r in v} for k, v in project.get("optional-dependencies", {}).items()}
    return {_name(r) for r in project["dependencies"]}, extras


def without_older_python_branches(tree: ast.AST) -> ast.AST:
    """``tree`` less the ``else`` of each ``if sys.version_info >= ...`` (a fallback for Pythons this install does
    not run on: ``tomli`` for ``tomllib`` on the slim install's 3.10, which ``deploy/pyproject.toml`` declares)."""
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "sys.version_info" in ast.unparse(node.test):
            node.orelse = []
    return tree


def imported_modules(source: str) -> set[str]:
    """Top-level names of the absolute imports in ``source``, lazy ones (inside functions) included."""
    out = set()
    for node in ast.walk(without_older_python_branches(ast.parse(source))):
        if isinstance(node, ast.Import):
            out.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module.split(".")[0])
    return out


def undeclared_imports(pyproject_text: str, files: dict[str, str]) -> list[str]:
    """One line per third-party import in ``files`` (relative path -> source) that no allowed
    requirement provides."""
    core, extras = declared(pyproject_text)
    providers = md.packages_distributions()
    local = {Path(r).stem for r in files if r.startswith(LOCAL_ROOTS) and r.endswith(".py")}
    problems = []
    for rel, source in sorted(files.items()):
        allowed, optional = set(core), set()
        for extra, users in EXTRA_USERS.items():
            if any(rel == u or (u.endswith("/") and rel.startswith(u)) for u in users):
                allowed |= extras.get(extra, set())
                optional |= extras.get(extra, set())
        folder = rel.rpartition("/")[0]
        for module in sorted(imported_modules(source)):
            if module in sys.stdlib_module_names or module in ("atrv_warp", "__future__"):
                continue
            if f"{folder}/{module}.py" in files or (rel.startswith(LOCAL_ROOTS) and module in local):
                continue  # a script's sibling, or a module of benchmarks/ or docs/, whose folders they put on sys.path
            dists = {_name(d) for d in providers.get(module, ())}
            if not dists and _name(module) in optional:
                continue  # an extra this file may use, not installed here (e.g. [bench]'s mujoco in CI)
            if not dists and module in FROM_A_ROS_INSTALL:
                continue
            if not dists:
                problems.append(f"{rel}: imports {module!r}, which no installed distribution provides")
            elif not dists & allowed:
                problems.append(f"{rel}: imports {module!r} from {sorted(dists)}, not declared for this file")
    return problems


def _project_files() -> dict[str, str]:
    files = {}
    for top in SCANNED:
        for path in sorted((ROOT / top).rglob("*.py")):
            files[path.relative_to(ROOT).as_posix()] = path.read_text()
    return files


def test_every_import_is_a_declared_dependency():
    problems = undeclared_imports((ROOT / "pyproject.toml").read_text(), _project_files())
    assert not problems, "\n".join(problems)


def test_the_check_catches_a_removed_dependency():
    """Removing matplotlib from the requirements makes the check name the file that needs it."""
    text = (ROOT / "pyproject.toml").read_text()
    pruned = re.sub(r'^\s*"matplotlib[^"]*",.*\n', "", text, flags=re.MULTILINE)
    assert pruned != text
    problems = undeclared_imports(pruned, _project_files())
    assert any(p.startswith("atrv_warp/rl/reporting.py: imports 'matplotlib'") for p in problems), problems
    # and an extra's module used from a core module is caught too
    leaky = undeclared_imports(text, {"atrv_warp/sim/simulator.py": "import rclpy\n"})
    assert len(leaky) == 1 and leaky[0].startswith("atrv_warp/sim/simulator.py: imports 'rclpy' from [")
    assert leaky[0].endswith("not declared for this file")
    # an extra's module (installed or not) is allowed only in the files declared as its users
    bench = undeclared_imports(text, {"atrv_warp/sim/simulator.py": "import mujoco\n",
                                      "benchmarks/perf/sim_vs_mujoco.py": "import mujoco\n"})
    assert len(bench) == 1 and bench[0].startswith("atrv_warp/sim/simulator.py: imports 'mujoco'"), bench
    # a script may import a module beside it or of benchmarks/ (docs/), and only there
    sibling = undeclared_imports(text, {"benchmarks/perf/a.py": "from _common import write_results\n",
                                        "benchmarks/_common.py": "import json\n",
                                        "examples/b.py": "import _common\n"})
    assert sibling == ["examples/b.py: imports '_common', which no installed distribution provides"], sibling


def test_wheel_carries_configs_urdf_and_policy(tmp_path):
    """A plain (non-editable) install gets the same defaults: the presets are package data."""
    # from a copy of the source: a build/ folder left in the checkout would let stale modules into the wheel
    src = tmp_path / "src"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(".git", "build", "runs", "*.egg-info", "__pycache__",
                                                             ".venv", "results"))
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(src)],
                   check=True, capture_output=True)
    (wheel,) = tmp_path.glob("atrv_warp-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for needed in ("atrv_warp/rl/configs/default.toml", "atrv_warp/rl/configs/smoke.toml", "atrv_warp/robots/atrvjr.urdf", "atrv_warp/robots/atrvjr.toml",
                   "atrv_warp/assets/pretrained_policy.pt", "atrv_warp/assets/nav_policy.pt",
                   "atrv_warp/assets/nav_policy_plain.pt",
                   "atrv_warp/rl/configs/nav.toml", "atrv_warp/py.typed"):
        assert needed in names, needed
    entry_points = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith("entry_points.txt"))).decode()
    assert "atrv-train = atrv_warp.cli.train:main" in entry_points


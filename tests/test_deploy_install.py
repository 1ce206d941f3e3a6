"""The slim install (``deploy/pyproject.toml``, the ``atrv-deploy`` distribution) in a fresh virtualenv that lacks
the simulator's packages: ``atrv-deploy --help``, the node's import, and the message-handling tests
(``tests/test_deploy.py``) run there.

No network: the fresh virtualenv sees torch, rclpy with its message packages, and pytest from this interpreter's
site-packages through a folder of links to just those distributions (and what they require), so Warp, Newton,
TorchRL, TensorDict and Rerun are absent there, as on a robot.
"""

from __future__ import annotations

import importlib.metadata as md
import json
import os
import re
import shutil
import subprocess
import sys
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
ROOTS = ("torch", "pytest", "ros-rclpy", "ros-geometry-msgs", "ros-nav-msgs", "ros-sensor-msgs", "ros-std-msgs",
         "ros-rcl-interfaces")
"""What the fresh virtualenv may see from here (with everything they require)."""
ABSENT = ("warp", "newton", "torchrl", "tensordict", "rerun", "atrv_warp.sim", "atrv_warp.task")


def _name(text: str) -> str:
    return re.sub(r"[-_.]+", "-", text).lower()


def closure(roots: tuple[str, ...]) -> set[str]:
    """The installed distributions ``roots`` need, transitively (requirements whose markers hold, no extras)."""
    from packaging.requirements import Requirement

    seen, todo = set(), [_name(r) for r in roots]
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        try:
            dist = md.distribution(name)
        except md.PackageNotFoundError:
            continue
        seen.add(name)
        for text in dist.requires or ():
            req = Requirement(text)
            if req.marker is None or req.marker.evaluate({"extra": ""}):
                todo.append(_name(req.name))
    return seen


def link_site(folder: Path, dists: set[str]) -> None:
    """Links in ``folder`` to each distribution's top-level entries in site-packages (its .dist-info included)."""
    folder.mkdir()
    for name in sorted(dists):
        dist = md.distribution(name)
        for f in dist.files or ():
            top = f.parts[0]
            if top in ("..", "__pycache__") or (folder / top).exists():
                continue
            source = Path(dist.locate_file(top))
            if source.exists():
                (folder / top).symlink_to(source)


@pytest.mark.slow  # builds a wheel and a virtualenv
def test_the_slim_install_runs_the_node_without_the_simulator(tmp_path):
    pytest.importorskip("rclpy", reason="ROS 2 extra not installed: pip install -e '.[ros]'")
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w",
                    str(wheels), str(ROOT / "deploy")], check=True, capture_output=True, text=True)
    (wheel,) = wheels.glob("atrv_deploy-*.whl")
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=False)
    python = env_dir / "bin" / "python"
    site = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                               check=True, capture_output=True, text=True).stdout.strip())
    dists = closure(ROOTS)
    assert not dists & {"warp-lang", "newton", "torchrl", "tensordict", "rerun-sdk"}, dists
    link_site(tmp_path / "links", dists)
    (site / "robot_site.pth").write_text(f"import site; site.addsitedir({str(tmp_path / 'links')!r})\n")
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--no-index", "-q",
                    str(wheel)], check=True, capture_output=True, text=True)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    work = tmp_path / "work"
    work.mkdir()

    def run(*args, **kw):
        return subprocess.run(list(args), cwd=work, env={**env, **kw}, capture_output=True, text=True, timeout=300,
                              check=False)

    helped = run(str(env_dir / "bin" / "atrv-deploy"), "--help")
    assert helped.returncode == 0 and "Parameters (--ros-args -p name:=value)" in helped.stdout, helped.stderr
    probe = ("import importlib.util, json, sys, atrv_warp, atrv_warp.deploy.node\n"
             f"print(json.dumps([atrv_warp.__file__, [m for m in {ABSENT!r} if importlib.util.find_spec(m.split('.')[0])"
             " is not None and (m.count('.') == 0 or importlib.util.find_spec(m) is not None)]]))\n")
    found = run(str(python), "-c", probe)
    assert found.returncode == 0, found.stderr
    where, present = json.loads(found.stdout)
    assert where.startswith(str(site)) and present == [], (where, present)
    # the message-handling tests, against a policy file written here (the slim install has no task spec to make one)
    sys.path.insert(0, str(ROOT / "tests"))
    from test_deploy import task_contract, write_policy

    policy = write_policy(tmp_path / "tiny.pt2", task_contract())
    shutil.copy(ROOT / "tests" / "test_deploy.py", work)
    tested = run(str(python), "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_deploy.py",
                 ATRV_DEPLOY_TEST_POLICY=str(policy))
    assert tested.returncode == 0, tested.stdout[-3000:] + tested.stderr[-2000:]
    summary = tested.stdout.strip().splitlines()[-1]
    assert re.search(r"\d+ passed, 1 skipped", summary), summary  # only the exporter's format check skips


def test_the_slim_files_keep_to_python_3_10():
    """What the slim install ships parses as Python 3.10 (ruff's syntax check for that version) and uses none of the
    standard library's 3.11 additions."""
    files = [ROOT / "atrv_warp" / n for n in ("__init__.py", "runtime.py")]
    files += sorted((ROOT / "atrv_warp" / "core").glob("*.py")) + sorted((ROOT / "atrv_warp" / "deploy").glob("*.py"))
    ruff = shutil.which("ruff") or str(Path(sys.executable).parent / "ruff")
    out = subprocess.run([ruff, "check", "--target-version", "py310", "--select", "E9,F", *map(str, files)],
                         capture_output=True, text=True, check=False)
    assert out.returncode == 0, out.stdout[-3000:]
    newer = re.compile(r"\btomllib\b|datetime\.UTC\b|\bStrEnum\b|typing\.Self\b|\bSelf\b|except\*|TaskGroup|"
                       r"\bfile_digest\b|\bExceptionGroup\b|\bLiteralString\b")
    # tomllib only behind a version check with tomli in its place, which the slim install requires on 3.10
    fallback = re.compile(r"if sys\.version_info >= \(3, 11\):.*\n    import tomllib\nelse:.*\n    import tomli as tomllib\n")
    texts = {f: fallback.sub("", f.read_text()) for f in files}
    hits = [f"{f.name}: {m.group(0)}" for f, text in texts.items() for m in newer.finditer(text)
            if not (m.group(0) == "tomllib" and fallback.search(f.read_text()))]
    assert not hits, hits
    if any(fallback.search(f.read_text()) for f in files):
        slim = (ROOT / "deploy" / "pyproject.toml").read_text()
        assert "\"tomli>=1.1; python_version < '3.11'\"" in slim, "the slim install must require tomli on 3.10"

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
    # nothing skips: the one reader of an exported file (core.contract) is the slim install's too
    assert re.fullmatch(r"\d+ passed in [\d.]+s", summary), summary


def _slim_files() -> list[Path]:
    """The Python files the slim install ships (``deploy/build_slim.py``'s ``FILES``)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("build_slim", ROOT / "deploy" / "build_slim.py")
    build_slim = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build_slim)
    return sorted({f for pattern in build_slim.FILES for f in (ROOT / "atrv_warp").glob(pattern) if f.suffix == ".py"})


def _python_3_10() -> str | None:
    """A Python 3.10 interpreter on this machine (ROS 2 Humble's): on the PATH, or one of pyenv's."""
    roots = [Path(os.environ.get("PYENV_ROOT", Path.home() / ".pyenv")), Path("/root/.pyenv")]
    candidates = [str(c) for root in roots for c in sorted(root.glob("versions/3.10*/bin/python3.10"))]
    candidates += [c for c in (shutil.which("python3.10"),) if c]  # a pyenv shim runs only where 3.10 is selected
    for candidate in candidates:
        ran = subprocess.run([candidate, "-c", "import sys; print(sys.version_info[:2] == (3, 10))"],
                             capture_output=True, text=True, check=False)
        if ran.returncode == 0 and ran.stdout.strip() == "True":
            return candidate
    return None


def test_the_slim_files_keep_to_python_3_10():
    """What the slim install ships uses nothing newer than Python 3.10 (vermin, from the package index, with the
    standard library's additions by version), and requires tomli where it reads robot files with tomllib's 3.10
    stand-in."""
    vermin = shutil.which("vermin") or str(Path(sys.executable).parent / "vermin")
    out = subprocess.run([vermin, "--target=3.10-", "--no-tips", "--violations", *map(str, _slim_files())],
                         capture_output=True, text=True, check=False)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-1000:]
    if any("import tomli as tomllib" in f.read_text() for f in _slim_files()):
        slim = (ROOT / "deploy" / "pyproject.toml").read_text()
        assert "\"tomli>=1.1; python_version < '3.11'\"" in slim, "the slim install must require tomli on 3.10"


@pytest.mark.slow  # builds a wheel and a virtualenv of another Python
def test_the_slim_wheel_installs_and_imports_on_python_3_10(tmp_path):
    """ROS 2 Humble's Python: the slim wheel builds under Python 3.10 and installs (``--no-deps``) into a fresh 3.10
    virtualenv, and every module it ships imports there up to torch and rclpy (the robot's own install provides
    them); the robot files load through tomli, which the slim install requires on 3.10."""
    python310 = _python_3_10()
    if python310 is None:
        pytest.skip("no Python 3.10 on this machine (pyenv install 3.10)")
    env_dir = tmp_path / "venv310"
    subprocess.run([python310, "-m", "venv", "--without-pip", str(env_dir)], check=True, capture_output=True)
    python = env_dir / "bin" / "python"
    site = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                               check=True, capture_output=True, text=True).stdout.strip())
    link_site(tmp_path / "links", {"tomli"})  # pure Python, as pip would install it on 3.10
    (site / "tomli_site.pth").write_text(f"import site; site.addsitedir({str(tmp_path / 'links')!r})\n")
    # built on 3.10 (its backend reads pyproject.toml with tomli there), then installed
    pip = [sys.executable, "-m", "pip", "--python", str(python)]
    wheels = tmp_path / "wheels"
    built = subprocess.run([*pip, "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(wheels),
                            str(ROOT / "deploy")], capture_output=True, text=True, check=False)
    assert built.returncode == 0, built.stderr[-3000:]
    (wheel,) = wheels.glob("atrv_deploy-*.whl")
    subprocess.run([*pip, "install", "--no-deps", "--no-index", "-q", str(wheel)], check=True, capture_output=True,
                   text=True)
    modules = sorted(".".join(f.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
                     for f in _slim_files() if not f.name.endswith(".launch.py"))  # ros2 launch runs those
    probe = f"""
import importlib, importlib.util, json, sys
assert sys.version_info[:2] == (3, 10), sys.version
stops = {{}}
for name in {modules!r}:
    try:
        importlib.import_module(name)
    except ModuleNotFoundError as err:
        stops[name] = err.name.split(".")[0]
# the robot files' reader alone (the package's core pulls torch in): the shipped robots load on 3.10, through tomli
spec = importlib.util.spec_from_file_location("robot_310", "{site}/atrv_warp/core/robot.py")
robot = sys.modules["robot_310"] = importlib.util.module_from_spec(spec)
spec.loader.exec_module(robot)
print(json.dumps([importlib.util.find_spec("atrv_warp").origin, stops, [robot.load_robot(n).name for n in robot.ROBOTS]]))
"""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    found = subprocess.run([str(python), "-c", probe], cwd=tmp_path, env=env, capture_output=True, text=True,
                           timeout=120, check=False)
    assert found.returncode == 0, found.stderr[-3000:]
    where, stops, robots = json.loads(found.stdout)
    assert where.startswith(str(site)) and sorted(robots) == ["atrvjr", "husky", "jackal"], (where, robots)
    # every module imports on 3.10 or stops only at what the robot's own install provides: torch, rclpy, messages
    assert set(stops.values()) <= {"torch", "rclpy", "geometry_msgs", "nav_msgs", "sensor_msgs", "std_msgs",
                                   "rcl_interfaces", "launch"}, stops
    assert "atrv_warp" not in stops and "atrv_warp.runtime" not in stops, stops

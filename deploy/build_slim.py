"""A PEP 517 build backend for ``atrv-deploy`` (``deploy/pyproject.toml``): the wheel of the deploy node alone.

It packs :data:`FILES` from the repository's ``atrv_warp`` (the light core, the deploy node, the package's
``__init__`` and console setup, the shipped robot files) with the metadata ``pyproject.toml`` declares. Only the
standard library is used (and on Python 3.10 tomli, tomllib's stand-in, which ``pyproject.toml``'s build-system
requires there), so on 3.11 and later ``pip install ./deploy`` builds offline with nothing to fetch for the build.
"""

from __future__ import annotations

import base64
import hashlib
import re
import sys
import zipfile
from pathlib import Path

if sys.version_info >= (3, 11):  # noqa: UP036 (the backend runs on 3.10)
    import tomllib
else:  # Python 3.10 (ROS 2 Humble's): the same parser, which pyproject.toml's build-system requires there
    import tomli as tomllib

HERE = Path(__file__).resolve().parent
SOURCE = HERE.parent / "atrv_warp"
FILES = ("__init__.py", "runtime.py", "py.typed", "core/*.py", "deploy/*.py", "deploy/launch/*.launch.py",
         "robots/*.toml", "robots/*.urdf")
"""What the wheel holds, relative to ``atrv_warp/``."""
TAG = "py3-none-any"


def _project() -> dict:
    return tomllib.loads((HERE / "pyproject.toml").read_text())["project"]


def _version() -> str:
    m = re.search(r'^__version__ = "([^"]+)"', (SOURCE / "__init__.py").read_text(), re.MULTILINE)
    return m.group(1)


def _metadata(project: dict, version: str) -> str:
    lines = ["Metadata-Version: 2.1", f"Name: {project['name']}", f"Version: {version}",
             f"Summary: {project['description']}", f"License: {project['license']['text']}",
             f"Requires-Python: {project['requires-python']}"]
    lines += [f"Requires-Dist: {r}" for r in project["dependencies"]]
    for extra, reqs in project.get("optional-dependencies", {}).items():
        lines.append(f"Provides-Extra: {extra}")
        lines += [f'Requires-Dist: {r}; extra == "{extra}"' for r in reqs]
    return "\n".join(lines) + "\n"


def _files() -> list[Path]:
    return sorted({p for pattern in FILES for p in SOURCE.glob(pattern) if "__pycache__" not in p.parts})


def _record_line(name: str, data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{name},sha256={digest},{len(data)}"


def get_requires_for_build_wheel(config_settings=None) -> list[str]:
    return []


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None) -> str:
    """Write ``atrv_deploy-<version>-py3-none-any.whl`` into ``wheel_directory``; returns its name."""
    project, version = _project(), _version()
    dist = f"{project['name'].replace('-', '_')}-{version}"
    name = f"{dist}-{TAG}.whl"
    scripts = "".join(f"{k} = {v}\n" for k, v in project.get("scripts", {}).items())
    entries = [(f"atrv_warp/{p.relative_to(SOURCE).as_posix()}", p.read_bytes()) for p in _files()]
    entries += [(f"{dist}.dist-info/METADATA", _metadata(project, version).encode()),
                (f"{dist}.dist-info/WHEEL", f"Wheel-Version: 1.0\nGenerator: build_slim\nRoot-Is-Purelib: true\n"
                                            f"Tag: {TAG}\n".encode()),
                (f"{dist}.dist-info/entry_points.txt", f"[console_scripts]\n{scripts}".encode())]
    record = "\n".join(_record_line(n, d) for n, d in entries) + f"\n{dist}.dist-info/RECORD,,\n"
    with zipfile.ZipFile(Path(wheel_directory) / name, "w", zipfile.ZIP_DEFLATED) as zf:
        for n, d in entries:
            zf.writestr(n, d)
        zf.writestr(f"{dist}.dist-info/RECORD", record)
    return name

"""The public API: ``atrv_warp.__all__`` is the contract, every module's ``__all__`` names what it
has, and the version is the one ``pyproject.toml`` declares.

Changing ``PUBLIC`` below changes the package's contract: say so in ``CHANGELOG.md``.
"""

from __future__ import annotations

import importlib
import pkgutil
import tomllib
from pathlib import Path

import pytest

import atrv_warp

ROOT = Path(__file__).resolve().parent.parent

PUBLIC = [
    "DRIVE_MODE_TORQUES", "END_REASONS", "VARIANTS", "ATRVjrEnv", "ArenaConfig", "ContactConfig", "DiffRollout",
    "DriveMode", "EndReason", "EnvFactory", "InertialOverride", "RoverConfig", "RoverEnv", "RoverSim", "SimBuffers", "SimConfig",
    "TaskConfig", "TrainConfig", "URDFError", "get_variant", "load_policy", "load_rover",
]


def _modules() -> list[str]:
    names = ["atrv_warp"]
    for info in pkgutil.walk_packages(atrv_warp.__path__, "atrv_warp."):
        names.append(info.name)
    return names


def test_the_top_level_names_are_the_contract():
    assert sorted(atrv_warp.__all__) == sorted(PUBLIC) and len(set(PUBLIC)) == len(PUBLIC)
    assert set(atrv_warp._EXPORTS) == set(atrv_warp.__all__)  # noqa: SLF001  (the lazy table serves the contract)
    for name in atrv_warp.__all__:
        obj = getattr(atrv_warp, name)  # the lazy import resolves
        home = getattr(obj, "__module__", None)
        assert home is None or home.startswith("atrv_warp."), (name, home)
    with pytest.raises(AttributeError, match="has no attribute 'Trainer'"):
        _ = atrv_warp.Trainer


INTERNAL = ("atrv_warp.sim.kernels", "atrv_warp.task.kernels")
"""Warp kernels and their structs: internal, reached through the classes that launch them."""
WITHOUT_ALL: tuple[str, ...] = ()
"""Modules that should name their public API and do not yet."""


@pytest.mark.parametrize("module", _modules())
def test_every_module_has_what_its_all_names(module):
    if module.startswith(("atrv_warp.integrations.ros.node", "atrv_warp.integrations.ros.drive")):
        pytest.importorskip("rclpy")
    mod = importlib.import_module(module)
    names = getattr(mod, "__all__", None)
    own = [n for n, v in vars(mod).items() if not n.startswith("_") and getattr(v, "__module__", None) == module]
    if names is None:
        assert not own or module.startswith(INTERNAL) or module in WITHOUT_ALL, \
            f"{module} defines {own} but has no __all__"
        return
    assert len(names) == len(set(names)), f"{module}: a name twice in __all__"
    missing = [n for n in names if not hasattr(mod, n)]
    assert not missing, f"{module}.__all__ names what it does not have: {missing}"


def test_version_and_type_marker():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert atrv_warp.__version__ == project["version"] == "0.2.0"
    assert (ROOT / "atrv_warp" / "py.typed").is_file()
    assert f"## {project['version']}" in (ROOT / "CHANGELOG.md").read_text()

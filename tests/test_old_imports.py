"""Old import paths keep working after issue 62 moved the modules (CHANGELOG.md says so): the command-line modules
into ``atrv_warp/cli/``, system identification from ``atrv_warp.integrations.calibration`` to
``atrv_warp.sim.sysid``, and the measurement protocols from ``atrv_warp.sim.checks`` to ``atrv_warp.sim.protocols``.
Each old path gives the very objects of the new one (every installed command answering ``--help``:
``tests/test_cli.py``)."""

from __future__ import annotations

import ast
import importlib
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

COMMANDS = ("train", "evaluate", "demo", "model", "export", "calibrate", "robot", "ros")
"""The command-line modules: ``atrv_warp.<name>`` (old, still ``python -m``'s) re-exports ``atrv_warp.cli.<name>``."""
PUBLIC_BEYOND_ALL = {"evaluate": ("MUJOCO_EXTRA",), "robot": ("AGREEMENT",)}
"""Public names the old modules had outside their ``__all__``."""
SYSID = ("excitation", "fit", "log", "output")


@pytest.mark.parametrize("name", COMMANDS)
def test_an_old_command_module_re_exports_the_new_one(name):
    old, new = importlib.import_module(f"atrv_warp.{name}"), importlib.import_module(f"atrv_warp.cli.{name}")
    assert old is not new and old.__all__ == new.__all__
    for attr in (*new.__all__, *PUBLIC_BEYOND_ALL.get(name, ())):
        assert getattr(old, attr) is getattr(new, attr), attr
    # the docs' command table reads the first line of the old module's docstring (docs/hooks.py, command_summary)
    first = ast.get_docstring(ast.parse((ROOT / "atrv_warp" / f"{name}.py").read_text())).splitlines()[0]
    assert first == new.__doc__.splitlines()[0]


def test_python_m_atrv_warp_train_help(run_module):
    """The README's command, through the old module."""
    out = run_module("atrv_warp.train", "--help").stdout
    assert "--resume" in out and "--config" in out


def test_the_old_calibration_package_is_sysid():
    import atrv_warp.integrations.calibration as old_package
    import atrv_warp.integrations.calibration.fit
    from atrv_warp.sim import sysid

    assert atrv_warp.integrations.calibration.fit is sysid.fit
    assert old_package.__all__ == sysid.__all__
    for name in sysid.__all__:
        assert getattr(old_package, name) is getattr(sysid, name), name
    for module in SYSID:
        old = importlib.import_module(f"atrv_warp.integrations.calibration.{module}")
        assert old is importlib.import_module(f"atrv_warp.sim.sysid.{module}") is sys.modules[old.__name__], module
        assert getattr(old_package, module) is old  # `from atrv_warp.integrations.calibration import fit`
    from atrv_warp.integrations.calibration.fit import _model_check  # private names too: it is the same module
    from atrv_warp.integrations.calibration.log import DriveLog

    assert _model_check is sysid.fit._model_check and DriveLog is sysid.DriveLog  # noqa: SLF001


def test_checks_re_exports_the_protocols_and_keeps_the_fingerprints():
    from atrv_warp.sim import checks, protocols

    assert set(protocols.__all__) < set(checks.__all__)
    for name in protocols.__all__:
        assert getattr(checks, name) is getattr(protocols, name), name
    for name in ("dynamics_fingerprint", "driver_fingerprint", "FINGERPRINT_STEPS"):
        assert name in checks.__all__ and not hasattr(protocols, name), name
    assert checks.dynamics_fingerprint.__module__ == "atrv_warp.sim.checks"

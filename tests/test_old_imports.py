"""Old import paths keep working after issues 62 and 69 moved the modules (CHANGELOG.md says so): the command-line
modules into ``atrv_warp/cli/`` (``python -m atrv_warp.train`` and the like stay), and until 0.3.0, each with a
``DeprecationWarning`` that names the new path: system identification from ``atrv_warp.integrations.calibration`` to
``atrv_warp.sim.sysid``, the measurement protocols and fingerprints from ``atrv_warp.sim.checks`` to
``atrv_warp.sim.protocols`` and ``atrv_warp.sim.fingerprints``, ``task_fingerprint`` from ``atrv_warp.task.evaluation``
to ``atrv_warp.task.fingerprints``. Each old path gives the very objects of the new one (every installed command
answering ``--help``: ``tests/test_cli.py``)."""

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


def fresh_import(name: str, new: str):
    """Import ``name`` as a first import would (its old modules dropped from ``sys.modules``), expecting the
    ``DeprecationWarning`` that names ``new``."""
    for module in [m for m in sys.modules if m == name or m.startswith(name + ".")]:
        del sys.modules[module]
    with pytest.warns(DeprecationWarning, match=f"{name} is deprecated and goes in 0.3.0: .*{new}"):
        return importlib.import_module(name)


def test_the_old_calibration_package_is_sysid():
    from atrv_warp.sim import sysid

    old_package = fresh_import("atrv_warp.integrations.calibration", "atrv_warp.sim.sysid")
    assert old_package.__all__ == sysid.__all__
    for name in sysid.__all__:
        assert getattr(old_package, name) is getattr(sysid, name), name
    for module in SYSID:
        old = fresh_import(f"atrv_warp.integrations.calibration.{module}", f"atrv_warp.sim.sysid.{module}")
        assert old is importlib.import_module(f"atrv_warp.sim.sysid.{module}") is sys.modules[old.__name__], module
        assert getattr(old_package, module) is old  # `from atrv_warp.integrations.calibration import fit`
    from atrv_warp.integrations.calibration.fit import _model_check  # private names too: it is the same module
    from atrv_warp.integrations.calibration.log import DriveLog

    assert _model_check is sysid.fit._model_check and DriveLog is sysid.DriveLog  # noqa: SLF001


def test_the_split_deploy_controller_keeps_its_old_names():
    """``deploy.controller`` split into contract, messages and controller (issue 69): every public name it held still
    imports from it until 0.3.0, as the very object in its new home."""
    from atrv_warp.core import contract as core_contract
    from atrv_warp.deploy import contract, controller, messages

    old = {"EXPORT_FORMAT": core_contract, "RATE_RANGE_HZ": contract, "Deployable": contract,
           "PolicyRefused": contract, "load_deployable": contract, "read_imu": messages, "read_odometry": messages,
           "read_scan": messages, "scan_geometry": messages, "STATES": controller, "TIME_LIMIT": controller,
           "Controller": controller, "Settings": controller, "Tick": controller}
    for name, home in old.items():
        assert getattr(controller, name) is getattr(home, name), name


def test_the_split_fit_module_keeps_its_old_names():
    """``sim.sysid.fit`` split into config, segments, replay, solver and fit (issue 69): every public name it held
    still imports from it until 0.3.0, as the very object in its new home."""
    from atrv_warp.sim.sysid import config, fit, segments

    old = {"COMMAND_SOURCES": config, "CONFOUNDED": config, "DEFAULT_FIT": config, "FIT_FIDELITY": config,
           "FIT_PARAMETERS": config, "MISFIT_FLOOR": config, "MOTOR_PARAMETERS": config, "CalibrationConfig": config,
           "CalibrationError": config, "sim_config_tables": config, "Segments": segments,
           "integral_from_effort": segments, "make_segments": segments, "CalibrationResult": fit, "calibrate": fit,
           "recording_noise": fit, "replay_errors": fit}
    for name, home in old.items():
        assert getattr(fit, name) is getattr(home, name), name


def test_checks_gives_the_protocols_and_the_fingerprints():
    from atrv_warp.sim import fingerprints, protocols

    checks = fresh_import("atrv_warp.sim.checks", "atrv_warp.sim.fingerprints")
    assert set(checks.__all__) == set(protocols.__all__) | set(fingerprints.__all__)
    for module in (protocols, fingerprints):
        for name in module.__all__:
            assert getattr(checks, name) is getattr(module, name), name
    assert checks.dynamics_fingerprint.__module__ == "atrv_warp.sim.fingerprints"


def test_the_task_fingerprint_from_evaluation():
    from atrv_warp.task import evaluation, fingerprints

    with pytest.warns(DeprecationWarning, match="moved to atrv_warp.task.fingerprints; this old path goes in 0.3.0"):
        assert evaluation.task_fingerprint is fingerprints.task_fingerprint
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        _ = evaluation.nothing


"""An exported policy's contract: the format this version writes and reads, and the one reader of a ``.pt2`` with it.

A ``.pt2`` (``python -m atrv_warp.export``) is a ``torch.export`` program and, beside it in the archive,
``atrv_warp.json``: what the program observes and commands, at what rate, on which robot
(:func:`atrv_warp.rl.export.contract` writes it). Every reader in the package reads the file here: the exporter's
own check (:func:`atrv_warp.rl.export.load_exported`), the deploy node (:func:`atrv_warp.deploy.contract.load_deployable`)
and the MuJoCo twin. The file is checked before torch loads it (:func:`atrv_warp.core.files.load_exported_program`):
nothing in it can run code.

Only torch and the standard library are imported (the deploy node's light core).
"""

from __future__ import annotations

import json
from pathlib import Path

import torch

from atrv_warp.core.files import ExportedFileError, load_exported_program

__all__ = ["CONTRACT_FILE", "EXPORT_FORMAT", "read_exported"]

EXPORT_FORMAT = "atrv_warp.exported_policy/3"
"""Format tag of an exported policy's contract (3: the action's kind, ``twist`` or ``torque``, and the observation's,
``robot`` or ``arena``). A reader refuses any other, naming both."""
CONTRACT_FILE = "atrv_warp.json"
"""The contract's name among the archive's extra files."""


def read_exported(path: str | Path) -> tuple[torch.export.ExportedProgram, dict]:
    """The exported program at ``path`` and its contract (a dict of :data:`EXPORT_FORMAT`), the file checked before
    torch loads it.

    Raises:
        FileNotFoundError: No such file.
        ExportedFileError: One line naming the file and the problem: refused by the check (nothing in it ran), no
            contract, or a contract of another format (export the policy again).
    """
    program, extra = load_exported_program(path)
    try:
        contract = json.loads(extra.get(CONTRACT_FILE, ""))
    except json.JSONDecodeError:
        raise ExportedFileError(f"{path}: no {CONTRACT_FILE} contract in the file (export the policy with python -m "
                                "atrv_warp.export POLICY OUT.pt2)") from None
    if not isinstance(contract, dict) or contract.get("format") != EXPORT_FORMAT:
        got = contract.get("format") if isinstance(contract, dict) else None
        raise ExportedFileError(f"{path}: contract format {got!r}, this version reads {EXPORT_FORMAT!r}: export the "
                                "policy again (python -m atrv_warp.export POLICY OUT.pt2)")
    return program, contract

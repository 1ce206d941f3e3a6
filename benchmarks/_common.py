"""What the benchmark scripts share: pinning to one core, and writing the results file.

The scripts run as ``python benchmarks/<name>.py``, so this folder is on ``sys.path`` and they
import it as ``_common``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path


def pin_to_one_core() -> None:
    """Run this process (and the threads it starts) on the lowest core it may use, where the OS
    allows it: one core for every measurement, so figures compare within a run."""
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


def write_results(path: str | Path, result: dict) -> Path:
    """Write ``result`` as indented JSON to ``path``, creating its folder; returns the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    return out

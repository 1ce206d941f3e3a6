"""Fit the simulator to a drive recorded on a rover: ``python -m atrv_warp.calibrate BAG [--out calibrated.toml]``.

The command lives in :mod:`atrv_warp.cli.calibrate`; this module keeps ``python -m atrv_warp.calibrate`` and
``from atrv_warp.calibrate import main`` working.
"""

import sys

from atrv_warp.cli.calibrate import build_parser, main

__all__ = ["build_parser", "main"]

if __name__ == "__main__":
    sys.exit(main())

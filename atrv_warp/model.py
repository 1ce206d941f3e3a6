"""Print the rover model as the reference does: ``python -m atrv_warp.model [--robot NAME] [--urdf PATH] [--variant NAME]``.

The command lives in :mod:`atrv_warp.cli.model`; this module keeps ``python -m atrv_warp.model`` and
``from atrv_warp.model import main`` working.
"""

import sys

from atrv_warp.cli.model import build_parser, main

__all__ = ["build_parser", "main"]

if __name__ == "__main__":
    sys.exit(main())

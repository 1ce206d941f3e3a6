"""Export a trained policy to a file that runs with torch alone: ``python -m atrv_warp.export [--onnx] [POLICY] OUT``.

The command lives in :mod:`atrv_warp.cli.export`; this module keeps ``python -m atrv_warp.export`` and
``from atrv_warp.export import main`` working.
"""

import sys

from atrv_warp.cli.export import build_parser, main

__all__ = ["build_parser", "main"]

if __name__ == "__main__":
    sys.exit(main())

"""Drive five ways side by side, one world each, and print what happened.

The command lives in :mod:`atrv_warp.cli.demo`; this module keeps ``python -m atrv_warp.demo`` and
``from atrv_warp.demo import main`` working.
"""

import sys

from atrv_warp.cli.demo import build_parser, main

__all__ = ["build_parser", "main"]

if __name__ == "__main__":
    sys.exit(main())

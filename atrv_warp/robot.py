"""Robot files: list the shipped ones, start one from a URDF, check and measure one.

The command lives in :mod:`atrv_warp.cli.robot`; this module keeps ``python -m atrv_warp.robot`` and
``from atrv_warp.robot import main`` working.
"""

import sys

from atrv_warp.cli.robot import (
    AGREEMENT,  # noqa: F401 - public before the move, not in __all__
    build_parser,
    format_check,
    main,
    starter_file,
    write_measured,
)

__all__ = ["build_parser", "format_check", "main", "starter_file", "write_measured"]

if __name__ == "__main__":
    sys.exit(main())

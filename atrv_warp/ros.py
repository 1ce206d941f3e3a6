"""ROS 2 base driver for simulated rovers (any robot file): ``python -m atrv_warp.ros [--ros-args -p name:=value …]``.

The command lives in :mod:`atrv_warp.cli.ros`; this module keeps ``python -m atrv_warp.ros`` and
``from atrv_warp.ros import main`` working.
"""

import sys

from atrv_warp.cli.ros import main

__all__ = ["main"]

if __name__ == "__main__":
    sys.exit(main())

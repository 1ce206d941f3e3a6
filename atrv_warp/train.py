"""Train a driver with TorchRL SAC or PPO: ``python -m atrv_warp.train``.

The command lives in :mod:`atrv_warp.cli.train`; this module keeps ``python -m atrv_warp.train`` and
``from atrv_warp.train import main`` working.
"""

import sys

from atrv_warp.cli.train import main

__all__ = ["main"]

if __name__ == "__main__":
    sys.exit(main())

"""``python -m atrv_warp.deploy POLICY.pt2``: the policy as a ROS 2 node (see :mod:`atrv_warp.deploy`)."""

import sys

from atrv_warp.deploy.cli import main

if __name__ == "__main__":
    sys.exit(main())

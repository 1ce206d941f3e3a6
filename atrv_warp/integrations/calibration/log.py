"""Moved to :mod:`atrv_warp.sim.sysid.log`; importing this old path gives that module itself."""

import sys

from atrv_warp.sim.sysid import log

sys.modules[__name__] = log

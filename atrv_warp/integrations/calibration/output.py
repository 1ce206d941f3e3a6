"""Moved to :mod:`atrv_warp.sim.sysid.output`; importing this old path gives that module itself."""

import sys

from atrv_warp.sim.sysid import output

sys.modules[__name__] = output

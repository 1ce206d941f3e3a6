"""Moved to :mod:`atrv_warp.sim.sysid.fit`; importing this old path gives that module itself."""

import sys

from atrv_warp.sim.sysid import fit

sys.modules[__name__] = fit

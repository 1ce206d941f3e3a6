"""Moved to :mod:`atrv_warp.sim.sysid.excitation`; importing this old path gives that module itself."""

import sys

from atrv_warp.sim.sysid import excitation

sys.modules[__name__] = excitation

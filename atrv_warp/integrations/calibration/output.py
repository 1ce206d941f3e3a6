"""Moved to :mod:`atrv_warp.sim.sysid.output`; importing this old path gives that module itself, with a
``DeprecationWarning``, until 0.3.0 removes it."""

import sys
import warnings

from atrv_warp.sim.sysid import output

warnings.warn("atrv_warp.integrations.calibration.output is deprecated and goes in 0.3.0: import atrv_warp.sim.sysid.output",
              DeprecationWarning, stacklevel=2)
sys.modules[__name__] = output

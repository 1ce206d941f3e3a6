"""Moved to :mod:`atrv_warp.sim.sysid.fit`; importing this old path gives that module itself, with a
``DeprecationWarning``, until 0.3.0 removes it."""

import sys
import warnings

from atrv_warp.sim.sysid import fit

warnings.warn("atrv_warp.integrations.calibration.fit is deprecated and goes in 0.3.0: import atrv_warp.sim.sysid.fit",
              DeprecationWarning, stacklevel=2)
sys.modules[__name__] = fit

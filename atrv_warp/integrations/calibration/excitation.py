"""Moved to :mod:`atrv_warp.sim.sysid.excitation`; importing this old path gives that module itself, with a
``DeprecationWarning``, until 0.3.0 removes it."""

import sys
import warnings

from atrv_warp.sim.sysid import excitation

warnings.warn("atrv_warp.integrations.calibration.excitation is deprecated and goes in 0.3.0: import atrv_warp.sim.sysid.excitation",
              DeprecationWarning, stacklevel=2)
sys.modules[__name__] = excitation

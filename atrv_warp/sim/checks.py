"""Moved: the simulator's fingerprints to :mod:`atrv_warp.sim.fingerprints`, the measurement protocols to
:mod:`atrv_warp.sim.protocols`. This old path still gives every name of both, with a ``DeprecationWarning``, until
0.3.0 removes it.
"""

import warnings

from atrv_warp.sim import fingerprints, protocols
from atrv_warp.sim.fingerprints import *
from atrv_warp.sim.protocols import *

__all__ = fingerprints.__all__ + protocols.__all__

warnings.warn("atrv_warp.sim.checks is deprecated and goes in 0.3.0: import the fingerprints from "
              "atrv_warp.sim.fingerprints and the measurement protocols from atrv_warp.sim.protocols",
              DeprecationWarning, stacklevel=2)

"""The old home of system identification, kept so that old imports work until 0.3.0 removes it (each with a
``DeprecationWarning``): it moved to :mod:`atrv_warp.sim.sysid`.

``from atrv_warp.integrations.calibration import calibrate`` gives :func:`atrv_warp.sim.sysid.calibrate`, and
``atrv_warp.integrations.calibration.fit`` (``.log``, ``.excitation``, ``.output``) *is* the module
``atrv_warp.sim.sysid.fit``: each of those files puts the new module in its place.
"""

import warnings

from atrv_warp.sim.sysid import *
from atrv_warp.sim.sysid import __all__  # noqa: F401

warnings.warn("atrv_warp.integrations.calibration is deprecated and goes in 0.3.0: import atrv_warp.sim.sysid",
              DeprecationWarning, stacklevel=2)

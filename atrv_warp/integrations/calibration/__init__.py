"""The old home of system identification, kept so that old imports work: it moved to :mod:`atrv_warp.sim.sysid`.

``from atrv_warp.integrations.calibration import calibrate`` gives :func:`atrv_warp.sim.sysid.calibrate`, and
``atrv_warp.integrations.calibration.fit`` (``.log``, ``.excitation``, ``.output``) *is* the module
``atrv_warp.sim.sysid.fit``: each of those files puts the new module in its place.
"""

from atrv_warp.sim.sysid import *
from atrv_warp.sim.sysid import __all__  # noqa: F401

"""The old home of system identification, kept so that old imports work: it moved to :mod:`atrv_warp.sim.sysid`.

``from atrv_warp.integrations.calibration import calibrate`` gives :func:`atrv_warp.sim.sysid.calibrate`, and
``atrv_warp.integrations.calibration.fit`` (``.log``, ``.excitation``, ``.output``) *is* the module
``atrv_warp.sim.sysid.fit``: each of those files puts the new module in its place.
"""

from atrv_warp.sim.sysid import (
    DEFAULT_FIT,
    FIT_PARAMETERS,
    BagError,
    CalibrationConfig,
    CalibrationError,
    CalibrationResult,
    DriveLog,
    Topics,
    calibrate,
    read_drive_log,
)

__all__ = ["DEFAULT_FIT", "FIT_PARAMETERS", "BagError", "CalibrationConfig", "CalibrationError", "CalibrationResult",
           "DriveLog", "Topics", "calibrate", "read_drive_log"]

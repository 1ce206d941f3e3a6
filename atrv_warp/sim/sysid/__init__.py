"""System identification: the simulator's physical parameters fitted to a drive recorded on a rover
(``python -m atrv_warp.calibrate``).

It replays the drive in the simulator and knows no task or trainer, so it lives beside the simulator. Before issue 62 it
was ``atrv_warp.integrations.calibration``, which still imports (the same modules and objects, with a
``DeprecationWarning``) until 0.3.0.

- :mod:`.log`: the drive read from a ROS 2 bag (MCAP): commands, wheel encoders, reference pose;
- :mod:`.config`: what the fit adjusts (the parameters and their bounds) and how (:class:`CalibrationConfig`);
- :mod:`.segments`: the drive cut into segments, each with its recorded start state and inputs;
- :mod:`.replay`: the segments replayed in the simulator, a batch of worlds with their own parameter values;
- :mod:`.solver`: Levenberg-Marquardt over the replays' residuals, and the sandwich standard errors;
- :mod:`.fit`: the whole calibration (:func:`calibrate`), its model check and its result;
- :mod:`.excitation`: the scripted drive a calibration bag records (seeded commands, no transport);
- :mod:`.output`: the simulator-config TOML, the JSON report and the plot of the paths.
"""

from atrv_warp.sim.sysid.config import DEFAULT_FIT, FIT_PARAMETERS, CalibrationConfig, CalibrationError
from atrv_warp.sim.sysid.fit import CalibrationResult, calibrate
from atrv_warp.sim.sysid.log import BagError, DriveLog, Topics, read_drive_log

__all__ = ["DEFAULT_FIT", "FIT_PARAMETERS", "BagError", "CalibrationConfig", "CalibrationError", "CalibrationResult",
           "DriveLog", "Topics", "calibrate", "read_drive_log"]

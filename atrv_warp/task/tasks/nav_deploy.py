"""``nav_deploy``: the nav world for a policy that runs on a robot.

Everything as :mod:`.nav`, but the policy commands ``/cmd_vel`` (``action="twist"``, up to 2 m/s and 2 rad/s) through a
base that accelerates at up to 1 m/s² (the Husky A200's ``diff_drive_controller``), and observes only what the robot
publishes (``observation="robot"``: the goal from wheel odometry, the odometry's twist, the IMU, the scan).
"""

import dataclasses

from atrv_warp.task.definition import Task
from atrv_warp.task.tasks import nav

CONFIG = dataclasses.replace(nav.CONFIG, action="twist", observation="robot", linear_max_acceleration=1.0)
TASK = Task("nav_deploy", CONFIG, nav.TASK.terms, nav.TASK.success, description=__doc__.splitlines()[0],
            source=__file__)

"""Nav2's ``NavigateToPose`` action for the deploy node: its definition per ROS 2 distribution, and its class.

A ROS installation's ``nav2_msgs`` is used where there is one (a robot running Nav2 has it). Where there is none
(rclpy from the package index), the action's type support is built from the definition of the distribution the
node runs on (``$ROS_DISTRO``, else :data:`DEFAULT_DISTRO`) by :mod:`atrv_warp.core.ros_interfaces`. The definitions
differ: Humble's result is an empty message; Jazzy and Kilted give an ``error_code`` and an ``error_msg``. From Iron
on, the middleware carries each type's hash (RIHS01), computed from the fields of the definition built, so a client
of another distribution's definition does not match.
"""

from __future__ import annotations

import os

from atrv_warp.core.ros_interfaces import Interfaces, load_interface

__all__ = ["DEFAULT_DISTRO", "NAVIGATE_TO_POSE", "SOURCES", "interfaces", "load_navigate_to_pose"]

NAVIGATE_TO_POSE: dict[str, str] = {
    'humble': '#goal definition\ngeometry_msgs/PoseStamped pose\nstring behavior_tree\n---\n#result definition\nstd_msgs/Empty result\n---\n#feedback definition\ngeometry_msgs/PoseStamped current_pose\nbuiltin_interfaces/Duration navigation_time\nbuiltin_interfaces/Duration estimated_time_remaining\nint16 number_of_recoveries\nfloat32 distance_remaining\n',
    'jazzy': '#goal definition\ngeometry_msgs/PoseStamped pose\nstring behavior_tree\n---\n#result definition\n\n# Error codes\n# Note: The expected priority order of the errors should match the message order\nuint16 NONE=0\n\nuint16 error_code\nstring error_msg\n---\n#feedback definition\ngeometry_msgs/PoseStamped current_pose\nbuiltin_interfaces/Duration navigation_time\nbuiltin_interfaces/Duration estimated_time_remaining\nint16 number_of_recoveries\nfloat32 distance_remaining\n',
    'kilted': '#goal definition\ngeometry_msgs/PoseStamped pose\nstring behavior_tree\n---\n#result definition\n\n# Error codes\n# Note: The expected priority order of the errors should match the message order\nuint16 NONE=0\nuint16 UNKNOWN=9000\nuint16 FAILED_TO_LOAD_BEHAVIOR_TREE=9001\nuint16 TF_ERROR=9002\nuint16 TIMEOUT=9003\n\nuint16 error_code\nstring error_msg\n---\n#feedback definition\ngeometry_msgs/PoseStamped current_pose\nbuiltin_interfaces/Duration navigation_time\nbuiltin_interfaces/Duration estimated_time_remaining\nint16 number_of_recoveries\nfloat32 distance_remaining\n',
}
"""``nav2_msgs/action/NavigateToPose.action`` as each distribution's branch of Nav2 defines it (:data:`SOURCES`)."""
SOURCES = {
    'humble': "ros-navigation/navigation2@70da81453d720659071e89d61fdb79bfc22f7a90:nav2_msgs/action/NavigateToPose.action",
    'jazzy': "ros-navigation/navigation2@acea1ef231385002edfdb68480aba466d0073fef:nav2_msgs/action/NavigateToPose.action",
    'kilted': "ros-navigation/navigation2@cb394620d91a01ec3bff47986f0d436afa11cdc4:nav2_msgs/action/NavigateToPose.action",
}
"""Where each definition was read (the last commit of the branch that changed the file)."""
DEFAULT_DISTRO = "kilted"
"""Without ``$ROS_DISTRO``: the distribution of the package index's rclpy (ros-rclpy 9, Kilted's)."""
_DEPENDS = ("action_msgs", "builtin_interfaces", "geometry_msgs", "std_msgs", "unique_identifier_msgs",
            "service_msgs")


def interfaces(distro: str | None = None) -> Interfaces:
    """``nav2_msgs`` holding ``NavigateToPose`` as ``distro`` (default: ``$ROS_DISTRO``, else :data:`DEFAULT_DISTRO`)
    defines it. Raises ``ValueError`` naming the distributions known."""
    distro = distro or os.environ.get("ROS_DISTRO") or DEFAULT_DISTRO
    if distro not in NAVIGATE_TO_POSE:
        raise ValueError(f"no NavigateToPose definition for ROS distribution {distro!r}; known: "
                         f"{', '.join(NAVIGATE_TO_POSE)}")
    return Interfaces("nav2_msgs", {"action/NavigateToPose.action": NAVIGATE_TO_POSE[distro]}, _DEPENDS, tag=distro)


def load_navigate_to_pose(distro: str | None = None, *, build: bool = True) -> tuple[type | None, str]:
    """(the ``NavigateToPose`` action class, where it came from), or (``None``, why not)."""
    try:
        found = interfaces(distro)
    except ValueError as err:
        return None, str(err)
    return load_interface(found, "action", "NavigateToPose", build=build)

"""Nav2's ``NavigateToPose`` and ``FollowPath`` actions for the deploy node: their definitions per ROS 2 distribution,
and their classes.

A ROS installation's ``nav2_msgs`` is used where there is one (a robot running Nav2 has it). Where there is none
(rclpy from the package index), the action's type support is built from the definition of the distribution the
node runs on (``$ROS_DISTRO``, else :data:`DEFAULT_DISTRO`) by :mod:`atrv_warp.core.ros_interfaces`, both actions
in one ``nav2_msgs``. The definitions differ: Humble's results carry no error code; Jazzy's and Kilted's give an
``error_code`` and an ``error_msg``, and their ``FollowPath`` goal a ``progress_checker_id``. From Iron on, the
middleware carries each type's hash (RIHS01), computed from the fields of the definition built, so a client
of another distribution's definition does not match.
"""

from __future__ import annotations

import os

from atrv_warp.core.ros_interfaces import Interfaces, load_interface

__all__ = ["DEFAULT_DISTRO", "FOLLOW_PATH", "FOLLOW_PATH_CODES", "FOLLOW_PATH_SOURCES", "NAVIGATE_TO_POSE", "SOURCES",
           "interfaces", "load_follow_path", "load_navigate_to_pose"]

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
FOLLOW_PATH: dict[str, str] = {
    'humble': '#goal definition\nnav_msgs/Path path\nstring controller_id\nstring goal_checker_id\n---\n#result definition\nstd_msgs/Empty result\n---\n#feedback definition\nfloat32 distance_to_goal\nfloat32 speed\n',
    'jazzy': '#goal definition\nnav_msgs/Path path\nstring controller_id\nstring goal_checker_id\nstring progress_checker_id\n---\n#result definition\n\n# Error codes\n# Note: The expected priority order of the errors should match the message order\nuint16 NONE=0\nuint16 UNKNOWN=100\nuint16 INVALID_CONTROLLER=101\nuint16 TF_ERROR=102\nuint16 INVALID_PATH=103\nuint16 PATIENCE_EXCEEDED=104\nuint16 FAILED_TO_MAKE_PROGRESS=105\nuint16 NO_VALID_CONTROL=106\nuint16 CONTROLLER_TIMED_OUT=107\n\nstd_msgs/Empty result\nuint16 error_code\nstring error_msg\n---\n#feedback definition\nfloat32 distance_to_goal\nfloat32 speed\n',
    'kilted': '#goal definition\nnav_msgs/Path path\nstring controller_id\nstring goal_checker_id\nstring progress_checker_id\n---\n#result definition\n\n# Error codes\n# Note: The expected priority order of the errors should match the message order\nuint16 NONE=0\nuint16 UNKNOWN=100\nuint16 INVALID_CONTROLLER=101\nuint16 TF_ERROR=102\nuint16 INVALID_PATH=103\nuint16 PATIENCE_EXCEEDED=104\nuint16 FAILED_TO_MAKE_PROGRESS=105\nuint16 NO_VALID_CONTROL=106\nuint16 CONTROLLER_TIMED_OUT=107\n\nstd_msgs/Empty result\nuint16 error_code\nstring error_msg\n---\n#feedback definition\nfloat32 distance_to_goal\nfloat32 speed\n',
}
"""``nav2_msgs/action/FollowPath.action`` as each distribution's branch of Nav2 defines it
(:data:`FOLLOW_PATH_SOURCES`): what the controller server serves on ``follow_path`` and the behaviour tree's ``FollowPath`` node sends."""
FOLLOW_PATH_SOURCES = {
    'humble': "ros-navigation/navigation2@70da81453d720659071e89d61fdb79bfc22f7a90:nav2_msgs/action/FollowPath.action",
    'jazzy': "ros-navigation/navigation2@3140a6a65c2ecbcf975dac94e3f3c64c0d9efc84:nav2_msgs/action/FollowPath.action",
    'kilted': "ros-navigation/navigation2@b71cccd8c47d4cb472db1c3a509af3821336933a:nav2_msgs/action/FollowPath.action",
}
"""Where each ``FollowPath`` definition was read (the last commit of the branch that changed the file)."""
FOLLOW_PATH_CODES = {"UNKNOWN": 100, "INVALID_CONTROLLER": 101, "TF_ERROR": 102, "INVALID_PATH": 103,
                     "PATIENCE_EXCEEDED": 104, "FAILED_TO_MAKE_PROGRESS": 105, "NO_VALID_CONTROL": 106,
                     "CONTROLLER_TIMED_OUT": 107}
"""Jazzy's and Kilted's ``FollowPath`` result codes by name (the definitions' constants); Humble's has none."""
DEFAULT_DISTRO = "kilted"
"""Without ``$ROS_DISTRO``: the distribution of the package index's rclpy (ros-rclpy 9, Kilted's)."""
_DEPENDS = ("action_msgs", "builtin_interfaces", "geometry_msgs", "nav_msgs", "std_msgs", "unique_identifier_msgs",
            "service_msgs")


def interfaces(distro: str | None = None) -> Interfaces:
    """``nav2_msgs`` holding ``NavigateToPose`` and ``FollowPath`` as ``distro`` (default: ``$ROS_DISTRO``, else
    :data:`DEFAULT_DISTRO`) defines them. Raises ``ValueError`` naming the distributions known."""
    distro = distro or os.environ.get("ROS_DISTRO") or DEFAULT_DISTRO
    if distro not in NAVIGATE_TO_POSE:
        raise ValueError(f"no NavigateToPose definition for ROS distribution {distro!r}; known: "
                         f"{', '.join(NAVIGATE_TO_POSE)}")
    return Interfaces("nav2_msgs", {"action/NavigateToPose.action": NAVIGATE_TO_POSE[distro],
                                    "action/FollowPath.action": FOLLOW_PATH[distro]}, _DEPENDS, tag=distro)


def load_navigate_to_pose(distro: str | None = None, *, build: bool = True) -> tuple[type | None, str]:
    """(the ``NavigateToPose`` action class, where it came from), or (``None``, why not)."""
    return _load("NavigateToPose", distro, build)


def load_follow_path(distro: str | None = None, *, build: bool = True) -> tuple[type | None, str]:
    """(the ``FollowPath`` action class, where it came from), or (``None``, why not)."""
    return _load("FollowPath", distro, build)


def _load(name: str, distro: str | None, build: bool) -> tuple[type | None, str]:
    try:
        found = interfaces(distro)
    except ValueError as err:
        return None, str(err)
    return load_interface(found, "action", name, build=build)

"""ROS 2 bags in MCAP format (``ros2 bag info/play`` read them), written with mcap-ros2-support:
:class:`BagWriter` and the message definitions it registers, without rclpy."""

from __future__ import annotations

__all__ = ["BagWriter", "pose_dict"]

_STRING_DEF = "string data\n"
_POSE_STAMPED_DEF = """std_msgs/Header header
geometry_msgs/Pose pose
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: geometry_msgs/Pose
geometry_msgs/Point position
geometry_msgs/Quaternion orientation
================================================================================
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z
================================================================================
MSG: geometry_msgs/Quaternion
float64 x 0
float64 y 0
float64 z 0
float64 w 1
"""



class BagWriter:
    """ROS 2 bag in MCAP format (``ros2 bag info/play`` read it), written with mcap-ros2-support."""

    def __init__(self, path: str):
        from mcap_ros2.writer import Writer

        self._fh = open(path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._fh)
        self._schemas = {
            "geometry_msgs/msg/PoseStamped": self._writer.register_msgdef("geometry_msgs/msg/PoseStamped",
                                                                          _POSE_STAMPED_DEF),
            "std_msgs/msg/String": self._writer.register_msgdef("std_msgs/msg/String", _STRING_DEF),
        }

    def write(self, topic: str, type_name: str, message: dict, stamp_ns: int) -> None:
        self._writer.write_message(topic=topic, schema=self._schemas[type_name], message=message,
                                   log_time=stamp_ns, publish_time=stamp_ns)

    def close(self) -> None:
        self._writer.finish()
        self._fh.close()


def pose_dict(msg) -> dict:
    """A PoseStamped as the nested dict :class:`BagWriter` writes."""
    p, q = msg.pose.position, msg.pose.orientation
    return {"header": {"stamp": {"sec": msg.header.stamp.sec, "nanosec": msg.header.stamp.nanosec},
                       "frame_id": msg.header.frame_id},
            "pose": {"position": {"x": p.x, "y": p.y, "z": p.z},
                     "orientation": {"x": q.x, "y": q.y, "z": q.z, "w": q.w}}}

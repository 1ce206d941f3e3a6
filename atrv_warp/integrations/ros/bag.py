"""ROS 2 bags in MCAP format (``ros2 bag info/play`` read them), written with mcap-ros2-support:
:class:`BagWriter` and the message definitions it registers, without rclpy. ``tf2_msgs/msg/TFMessage``
(/tf, /tf_static) is written from its definition text too, so a bag carries the frame tree although
no tf2_msgs type support is installed. Reading them back is
:mod:`atrv_warp.sim.sysid.log`'s job."""

from __future__ import annotations

__all__ = ["RECORDED_TYPES", "BagWriter", "joint_state_dict", "message_definition", "odometry_dict", "pose_dict",
           "twist_dict"]

_DEFINITIONS = {  # ROS 2 message definitions (ros2msg), each with the types it uses
    "std_msgs/String": ("string data", ()),
    "builtin_interfaces/Time": ("int32 sec\nuint32 nanosec", ()),
    "std_msgs/Header": ("builtin_interfaces/Time stamp\nstring frame_id", ("builtin_interfaces/Time",)),
    "geometry_msgs/Point": ("float64 x\nfloat64 y\nfloat64 z", ()),
    "geometry_msgs/Vector3": ("float64 x\nfloat64 y\nfloat64 z", ()),
    "geometry_msgs/Quaternion": ("float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1", ()),
    "geometry_msgs/Pose": ("geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation",
                           ("geometry_msgs/Point", "geometry_msgs/Quaternion")),
    "geometry_msgs/Twist": ("geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular", ("geometry_msgs/Vector3",)),
    "geometry_msgs/PoseStamped": ("std_msgs/Header header\ngeometry_msgs/Pose pose",
                                  ("std_msgs/Header", "geometry_msgs/Pose")),
    "geometry_msgs/PoseWithCovariance": ("geometry_msgs/Pose pose\nfloat64[36] covariance", ("geometry_msgs/Pose",)),
    "geometry_msgs/TwistWithCovariance": ("geometry_msgs/Twist twist\nfloat64[36] covariance",
                                          ("geometry_msgs/Twist",)),
    "nav_msgs/Odometry": (("std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n"
                           "geometry_msgs/TwistWithCovariance twist"),
                          ("std_msgs/Header", "geometry_msgs/PoseWithCovariance", "geometry_msgs/TwistWithCovariance")),
    "sensor_msgs/JointState": (("std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
                                "float64[] effort"), ("std_msgs/Header",)),
    "geometry_msgs/Transform": ("geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation",
                                ("geometry_msgs/Vector3", "geometry_msgs/Quaternion")),
    "geometry_msgs/TransformStamped": ("std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform",
                                       ("std_msgs/Header", "geometry_msgs/Transform")),
    # tf2_msgs is not on the package index: its one message, written from its definition
    "tf2_msgs/TFMessage": ("geometry_msgs/TransformStamped[] transforms", ("geometry_msgs/TransformStamped",)),
}
RECORDED_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/Twist", "nav_msgs/msg/Odometry",
                  "sensor_msgs/msg/JointState", "std_msgs/msg/String", "tf2_msgs/msg/TFMessage")
"""Message types :class:`BagWriter` writes."""


def message_definition(type_name: str) -> str:
    """The full ROS 2 definition of ``type_name`` (``pkg/msg/Name``) as a bag stores it: its own fields,
    then each type it uses after a ``MSG:`` line."""
    root = type_name.replace("/msg/", "/")
    order, todo = [], [root]
    while todo:
        name = todo.pop(0)
        if name not in order:
            order.append(name)
            todo.extend(_DEFINITIONS[name][1])
    parts = [_DEFINITIONS[root][0]]
    for name in order[1:]:
        parts.append("=" * 80 + f"\nMSG: {name}\n{_DEFINITIONS[name][0]}")
    return "\n".join(parts) + "\n"


class BagWriter:
    """ROS 2 bag in MCAP format (``ros2 bag info/play`` read it), written with mcap-ros2-support."""

    def __init__(self, path: str):
        from mcap_ros2.writer import Writer

        self._fh = open(path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._fh)
        self._schemas = {name: self._writer.register_msgdef(name, message_definition(name)) for name in RECORDED_TYPES}

    def write(self, topic: str, type_name: str, message: dict, stamp_ns: int) -> None:
        self._writer.write_message(topic=topic, schema=self._schemas[type_name], message=message,
                                   log_time=stamp_ns, publish_time=stamp_ns)

    def close(self) -> None:
        self._writer.finish()
        self._fh.close()


def header_dict(header) -> dict:
    return {"stamp": {"sec": header.stamp.sec, "nanosec": header.stamp.nanosec}, "frame_id": header.frame_id}


def _pose(pose) -> dict:
    p, q = pose.position, pose.orientation
    return {"position": {"x": p.x, "y": p.y, "z": p.z}, "orientation": {"x": q.x, "y": q.y, "z": q.z, "w": q.w}}


def _vector(v) -> dict:
    return {"x": v.x, "y": v.y, "z": v.z}


def twist_dict(msg) -> dict:
    """A ``geometry_msgs/Twist`` as the nested dict :class:`BagWriter` writes."""
    return {"linear": _vector(msg.linear), "angular": _vector(msg.angular)}


def pose_dict(msg) -> dict:
    """A PoseStamped as the nested dict :class:`BagWriter` writes."""
    return {"header": header_dict(msg.header), "pose": _pose(msg.pose)}


def odometry_dict(msg) -> dict:
    """A ``nav_msgs/Odometry`` as the nested dict :class:`BagWriter` writes."""
    return {"header": header_dict(msg.header), "child_frame_id": msg.child_frame_id,
            "pose": {"pose": _pose(msg.pose.pose), "covariance": list(msg.pose.covariance)},
            "twist": {"twist": twist_dict(msg.twist.twist), "covariance": list(msg.twist.covariance)}}


def joint_state_dict(msg) -> dict:
    """A ``sensor_msgs/JointState`` as the nested dict :class:`BagWriter` writes."""
    return {"header": header_dict(msg.header), "name": list(msg.name), "position": list(msg.position),
            "velocity": list(msg.velocity), "effort": list(msg.effort)}

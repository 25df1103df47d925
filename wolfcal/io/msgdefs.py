"""ROS 2 message definitions (`ros2msg` schema text) of the messages in a capture file.

Written from the ROS 2 interface specifications (rcl_interfaces/common_interfaces, Humble and later). Each
definition is the message's own fields followed by every type it uses, each after a line of '=' and
`MSG: pkg/Type`: the layout rosbag2 stores and mcap_ros2 parses. Also: header stamps <-> nanoseconds, and the
names of wolfcal's own records in a capture (attachments, metadata), which the reader needs without the writer.
"""

from __future__ import annotations

JOINT_STATE = "sensor_msgs/msg/JointState"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
MARKERS = "mocap4r2_msgs/msg/Markers"  # MOCAP4ROS2's marker set (motion capture)
IMU = "sensor_msgs/msg/Imu"

URDF_ATTACHMENT = "robot.urdf"
CONFIG_ATTACHMENT = "robot.yaml"
CAMERAS_METADATA = "wolfcal.cameras"  # metadata record: camera name -> image topic
LIBRARY = "wolfcal"

_SEPARATOR = "=" * 80

_TIME = """int32 sec
uint32 nanosec
"""

_HEADER = """builtin_interfaces/Time stamp
string frame_id
"""

_REGION_OF_INTEREST = """uint32 x_offset
uint32 y_offset
uint32 height
uint32 width
bool do_rectify
"""

_JOINT_STATE = """std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
"""

_COMPRESSED_IMAGE = """std_msgs/Header header
string format
uint8[] data
"""

_CAMERA_INFO = """std_msgs/Header header
uint32 height
uint32 width
string distortion_model
float64[] d
float64[9] k
float64[9] r
float64[12] p
uint32 binning_x
uint32 binning_y
sensor_msgs/RegionOfInterest roi
"""


_MARKERS = """std_msgs/Header header
uint32 frame_number
mocap4r2_msgs/Marker[] markers
"""

_MARKER = """int8 USE_NAME=0
int8 USE_INDEX=1
int8 USE_BOTH=2
int8 id_type
int32 marker_index
string marker_name
geometry_msgs/Point translation
"""

_POINT = """float64 x
float64 y
float64 z
"""

_IMU = """std_msgs/Header header
geometry_msgs/Quaternion orientation
float64[9] orientation_covariance
geometry_msgs/Vector3 angular_velocity
float64[9] angular_velocity_covariance
geometry_msgs/Vector3 linear_acceleration
float64[9] linear_acceleration_covariance
"""

_QUATERNION = """float64 x 0
float64 y 0
float64 z 0
float64 w 1
"""


def _with_dependencies(definition: str, *dependencies: tuple[str, str]) -> str:
    parts = [definition]
    for name, text in dependencies:
        parts.append(f"{_SEPARATOR}\nMSG: {name}\n{text}")
    return "".join(parts)


_HEADER_DEPS = (("std_msgs/Header", _HEADER), ("builtin_interfaces/Time", _TIME))

#: schema name -> full `ros2msg` definition text
MSGDEFS: dict[str, str] = {
    JOINT_STATE: _with_dependencies(_JOINT_STATE, *_HEADER_DEPS),
    COMPRESSED_IMAGE: _with_dependencies(_COMPRESSED_IMAGE, *_HEADER_DEPS),
    CAMERA_INFO: _with_dependencies(_CAMERA_INFO, *_HEADER_DEPS, ("sensor_msgs/RegionOfInterest", _REGION_OF_INTEREST)),
    MARKERS: _with_dependencies(
        _MARKERS, *_HEADER_DEPS, ("mocap4r2_msgs/Marker", _MARKER), ("geometry_msgs/Point", _POINT)
    ),
    IMU: _with_dependencies(
        _IMU, *_HEADER_DEPS, ("geometry_msgs/Quaternion", _QUATERNION), ("geometry_msgs/Vector3", _POINT)
    ),
}


def stamp_dict(stamp_ns: int) -> dict:
    """builtin_interfaces/Time (as a dict for the CDR encoder) of a time in nanoseconds."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return {"sec": sec, "nanosec": nanosec}


def header_stamp_ns(header, log_time: int) -> int:
    """Stamp of a decoded std_msgs/Header [ns]; the message's log time when the publisher left it at zero."""
    return stamp_ns(header.stamp.sec, header.stamp.nanosec, log_time)


def stamp_ns(sec: int, nanosec: int, log_time: int) -> int:
    """A header stamp (sec, nanosec) in nanoseconds; the message's log time [ns] when the publisher left it at
    zero."""
    return int(sec) * 1_000_000_000 + int(nanosec) or int(log_time)

"""ROS 2 message definitions of the bag export (`sea-hil export --ros2`) in the `ros2msg` schema format.

The standard types (builtin_interfaces, std_msgs, sensor_msgs, rcl_interfaces, diagnostic_msgs, and the CAN frame
types of ros2_socketcan: `can_msgs/Frame`, `ros2_socketcan_msgs/FdFrame`) are written here field by field, as
their packages declare them (constants included, comments left out: decoders read fields only). The project's own
types live as `.msg` files in the package data (`sea_hil/ros2/sea_hil_msgs/msg/`), so users can build them into a
ROS 2 package. `full_text(type_name)` is the schema record's data as rosbag2 writes it: the type's own text, then
each type it depends on (depth first, once) after a line of 80 `=` and `MSG: pkg/Name`, so a reader decodes every
message from the bag file alone.
"""
from __future__ import annotations

import functools
import re
from importlib import resources

from sea_hil.errors import RecordingError

SEA_HIL_PACKAGE = "sea_hil_msgs"
SEPARATOR = "=" * 80

# "pkg/Name" -> definition text (rosidl .msg syntax)
STANDARD: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "sensor_msgs/JointState": ("std_msgs/Header header\n\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
                               "float64[] effort\n"),
    "can_msgs/Frame": ("std_msgs/Header header\nuint32 id\nbool is_rtr\nbool is_extended\nbool is_error\nuint8 dlc\n"
                       "uint8[8] data\n"),
    "ros2_socketcan_msgs/FdFrame": ("std_msgs/Header header\nuint32 id\nbool is_extended\nbool is_error\nuint8 len\n"
                                    "uint8[<=64] data\n"),
    "rcl_interfaces/Log": ("uint8 DEBUG=10\nuint8 INFO=20\nuint8 WARN=30\nuint8 ERROR=40\nuint8 FATAL=50\n\n"
                           "builtin_interfaces/Time stamp\nuint8 level\nstring name\nstring msg\nstring file\n"
                           "string function\nuint32 line\n"),
    "diagnostic_msgs/DiagnosticArray": "std_msgs/Header header\nDiagnosticStatus[] status\n",
    "diagnostic_msgs/DiagnosticStatus": ("byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\n\nbyte level\n"
                                         "string name\nstring message\nstring hardware_id\nKeyValue[] values\n"),
    "diagnostic_msgs/KeyValue": "string key\nstring value\n",
}
SEA_HIL_TYPES = ("LimbState", "Setpoint")
PRIMITIVES = frozenset({"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
                        "uint32", "int64", "uint64", "string", "wstring"})
# the field's type at the start of a line: "pkg/Name[] field", "uint8[<=64] data", "string<=10 s"
_FIELD_TYPE = re.compile(r"^\s*([A-Za-z][A-Za-z0-9_/]*)")


def short_name(type_name: str) -> str:
    """`sensor_msgs/msg/JointState` -> `sensor_msgs/JointState` (the form of field types and `MSG:` lines)."""
    parts = type_name.split("/")
    if len(parts) == 3 and parts[1] == "msg":
        return f"{parts[0]}/{parts[2]}"
    if len(parts) == 2:
        return type_name
    raise RecordingError(f"not a ROS 2 message type name: {type_name!r}")


def full_name(type_name: str) -> str:
    """`std_msgs/Header` -> `std_msgs/msg/Header` (the form of schema names and metadata.yaml types)."""
    pkg, name = short_name(type_name).split("/")
    return f"{pkg}/msg/{name}"


@functools.cache
def definition(type_name: str) -> str:
    """The `.msg` text of one type (standard, or shipped in `sea_hil_msgs`)."""
    key = short_name(type_name)
    if key in STANDARD:
        return STANDARD[key]
    pkg, name = key.split("/")
    if pkg == SEA_HIL_PACKAGE and name in SEA_HIL_TYPES:
        return (resources.files("sea_hil.ros2").joinpath(f"{SEA_HIL_PACKAGE}/msg/{name}.msg")
                .read_text(encoding="utf-8"))
    raise RecordingError(f"no message definition for {type_name!r}")


def dependencies(type_name: str) -> list[str]:
    """The non-primitive field types of one type, as `pkg/Name`, in field order (same-package names qualified)."""
    pkg = short_name(type_name).split("/")[0]
    out: list[str] = []
    for line in definition(type_name).splitlines():
        tokens = line.split("#", 1)[0].split()
        if len(tokens) < 2 or "=" in tokens[1]:
            continue   # blank, or a constant ("uint8 DEBUG=10")
        m = _FIELD_TYPE.match(tokens[0])
        if m is None:
            continue
        base = m.group(1)
        if base in PRIMITIVES:
            continue
        if base == "Header":
            base = "std_msgs/Header"
        dep = base if "/" in base else f"{pkg}/{base}"
        if dep not in out:
            out.append(dep)
    return out


@functools.cache
def full_text(type_name: str) -> str:
    """The concatenated `ros2msg` schema text of `type_name`: its definition, then every dependency once."""
    seen: list[str] = []

    def visit(t: str) -> None:
        for dep in dependencies(t):
            if dep not in seen:
                seen.append(dep)
                visit(dep)

    visit(short_name(type_name))
    parts = [definition(type_name)]
    parts += [f"{SEPARATOR}\nMSG: {dep}\n{definition(dep)}" for dep in seen]
    return "\n".join(parts)

"""Pure codec for Universal Robots' RTDE protocol, version 2 (TCP port 30004).

Wire format (all big-endian):

* every package = header ``uint16 size`` (counts the 3 header bytes too) + ``uint8 type``, then the payload;
* ``V`` (86) request protocol version: ``uint16 version`` (2) -> reply ``uint8 accepted``;
* ``v`` (118) get URControl version: empty -> reply ``4 x uint32`` major, minor, bugfix, build;
* ``O`` (79) setup outputs: ``float64 frequency (Hz)`` + comma-joined variable names (ur_rtde appends a trailing
  comma) -> reply ``uint8 recipe id`` + comma-joined type names, ``NOT_FOUND`` in the slot of an unknown name;
* ``I`` (73) setup inputs: comma-joined names -> reply ``uint8 recipe id`` + types, ``IN_USE`` where a fieldbus
  (EtherNet/IP, PROFINET, MODBUS) already owns the register;
* ``S`` (83) start / ``P`` (80) pause: empty -> reply ``uint8 accepted``;
* ``U`` (85) data package: ``uint8 recipe id`` + the recipe's fields packed back to back (DOUBLE 8 B, VECTOR6D
  48 B, VECTOR3D 24 B, INT32/UINT32 4 B, UINT64 8 B, VECTOR6INT32/VECTOR6UINT32 24 B, BOOL/UINT8 1 B);
* ``M`` (77) text message (v2): ``uint8 length`` + message + ``uint8 length`` + source + ``uint8 warning level``.

A request and its reply share the type byte; which one a package is follows from who sent it, so this module has
a ``encode_*``/``decode_*`` pair for each direction. Clients such as ur_rtde parse ``U`` packages with their own
per-variable type table (:data:`VARIABLE_TYPES` restates the part this project uses), not with the types the
server names in its ``O`` reply.

Sources: UR's RTDE guide and its Python client (``rtde/serialize.py``), ur_rtde's ``rtde.cpp``; summarised in the
project's hardware notes. This module does no I/O: it turns bytes into :class:`RtdePackage` values and back.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum

from protocols.errors import ProtocolError

RTDE_PORT = 30004
PROTOCOL_VERSION = 2
HEADER_SIZE = 3
MAX_PACKAGE_SIZE = 0xFFFF  # the size field is a uint16


class PackageType(IntEnum):
    """RTDE package type bytes (ASCII letters)."""

    REQUEST_PROTOCOL_VERSION = ord("V")
    GET_URCONTROL_VERSION = ord("v")
    TEXT_MESSAGE = ord("M")
    DATA_PACKAGE = ord("U")
    CONTROL_PACKAGE_SETUP_OUTPUTS = ord("O")
    CONTROL_PACKAGE_SETUP_INPUTS = ord("I")
    CONTROL_PACKAGE_START = ord("S")
    CONTROL_PACKAGE_PAUSE = ord("P")


_KNOWN_TYPES = frozenset(int(t) for t in PackageType)

NOT_FOUND = "NOT_FOUND"
IN_USE = "IN_USE"

# struct format (without byte order) of each RTDE field type.
FIELD_FORMATS: dict[str, str] = {
    "BOOL": "?",
    "UINT8": "B",
    "INT32": "i",
    "UINT32": "I",
    "UINT64": "Q",
    "DOUBLE": "d",
    "VECTOR3D": "3d",
    "VECTOR6D": "6d",
    "VECTOR6INT32": "6i",
    "VECTOR6UINT32": "6I",
}
_FIELD_COUNTS = {name: struct.calcsize(code) // struct.calcsize(code[-1]) for name, code in FIELD_FORMATS.items()}

# Output variables (controller -> client) with their RTDE types; the subset ur_rtde's receive interface reads.
VARIABLE_TYPES: dict[str, str] = {
    "timestamp": "DOUBLE",  # s since controller start
    "target_q": "VECTOR6D",
    "target_qd": "VECTOR6D",
    "target_qdd": "VECTOR6D",
    "target_current": "VECTOR6D",
    "target_moment": "VECTOR6D",
    "actual_q": "VECTOR6D",  # rad
    "actual_qd": "VECTOR6D",
    "actual_current": "VECTOR6D",
    "joint_control_output": "VECTOR6D",
    "actual_TCP_pose": "VECTOR6D",  # m, rotation vector rad, base frame
    "actual_TCP_speed": "VECTOR6D",  # m/s, rad/s
    "actual_TCP_force": "VECTOR6D",  # N, N*m, base-frame axes about the TCP
    "target_TCP_pose": "VECTOR6D",
    "target_TCP_speed": "VECTOR6D",
    "ft_raw_wrench": "VECTOR6D",
    "actual_digital_input_bits": "UINT64",
    "actual_digital_output_bits": "UINT64",
    "joint_temperatures": "VECTOR6D",
    "actual_execution_time": "DOUBLE",
    "robot_mode": "INT32",  # -1 no controller ... 7 running
    "joint_mode": "VECTOR6INT32",
    "safety_mode": "INT32",  # 1 normal, 3 protective stop, ...
    "safety_status": "INT32",
    "actual_tool_accelerometer": "VECTOR3D",
    "speed_scaling": "DOUBLE",
    "target_speed_fraction": "DOUBLE",
    "actual_momentum": "DOUBLE",
    "actual_main_voltage": "DOUBLE",
    "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE",
    "actual_joint_voltage": "VECTOR6D",
    "runtime_state": "UINT32",
    "robot_status_bits": "UINT32",
    "safety_status_bits": "UINT32",  # bit 2 protective stop, bit 7 emergency stop
    "standard_analog_input0": "DOUBLE",
    "standard_analog_input1": "DOUBLE",
    "standard_analog_output0": "DOUBLE",
    "standard_analog_output1": "DOUBLE",
    "payload": "DOUBLE",
    "payload_cog": "VECTOR3D",
    "payload_inertia": "VECTOR6D",
    "output_bit_registers0_to_31": "UINT32",
    "output_bit_registers32_to_63": "UINT32",
}

# Registers: output_int_register_0..47 INT32, output_double_register_0..47 DOUBLE, bit registers 64..127 BOOL;
# the same names with ``input_`` are the client -> controller registers.
_REGISTER_PATTERN = re.compile(r"^(input|output)_(int|double|bit)_register_(\d+)$")
_REGISTER_TYPES = {"int": "INT32", "double": "DOUBLE", "bit": "BOOL"}

# Safety status bits (``safety_status_bits``).
SAFETY_BIT_PROTECTIVE_STOP = 1 << 2
SAFETY_BIT_EMERGENCY_STOP = 1 << 7
SAFETY_BIT_NORMAL_MODE = 1 << 0


def variable_type(name: str) -> str | None:
    """The RTDE type of a variable name, or None if this codec does not know it."""
    if name in VARIABLE_TYPES:
        return VARIABLE_TYPES[name]
    match = _REGISTER_PATTERN.match(name)
    if match is None:
        return None
    kind, index = match.group(2), int(match.group(3))
    if kind == "bit":
        return "BOOL" if 64 <= index <= 127 else None
    return _REGISTER_TYPES[kind] if 0 <= index <= 47 else None


FieldValue = float | int | bool | tuple[float, ...] | tuple[int, ...]


@dataclass(frozen=True, slots=True)
class RtdePackage:
    """One framed package: its type byte and its payload (header stripped)."""

    type: int
    payload: bytes

    def encode(self) -> bytes:
        return encode_package(self.type, self.payload)


@dataclass(frozen=True, slots=True)
class ControllerVersion:
    major: int
    minor: int
    bugfix: int
    build: int


@dataclass(frozen=True, slots=True)
class RecipeReply:
    """Reply to ``O``/``I``: the recipe id and one type name per requested variable (or NOT_FOUND / IN_USE)."""

    recipe_id: int
    types: tuple[str, ...]

    @property
    def ok(self) -> bool:
        return not any(t in (NOT_FOUND, IN_USE) for t in self.types)


@dataclass(frozen=True, slots=True)
class TextMessage:
    message: str
    source: str
    warning_level: int


# ---- framing --------------------------------------------------------------------------------------------------


def encode_package(package_type: int, payload: bytes = b"") -> bytes:
    """Frame ``payload`` with the 3-byte header."""
    size = HEADER_SIZE + len(payload)
    if size > MAX_PACKAGE_SIZE:
        raise ProtocolError(f"RTDE package of {size} bytes does not fit the uint16 size field")
    return struct.pack(">HB", size, package_type) + payload


class RtdePackageParser:
    """Incremental framer: ``feed`` bytes as they arrive from the socket, get whole packages back.

    A header with an unknown type byte or an impossible size (< 3) means the stream lost its framing; the parser
    then drops one byte at a time until a plausible header appears and counts the dropped bytes in
    ``dropped_bytes`` (RTDE has no sync marker, so this is a best effort).
    """

    def __init__(self) -> None:
        self._buffer = bytearray()
        self.dropped_bytes = 0

    def feed(self, data: bytes) -> list[RtdePackage]:
        self._buffer.extend(data)
        packages: list[RtdePackage] = []
        while len(self._buffer) >= HEADER_SIZE:
            size, package_type = struct.unpack_from(">HB", self._buffer)
            if size < HEADER_SIZE or package_type not in _KNOWN_TYPES:
                del self._buffer[0]
                self.dropped_bytes += 1
                continue
            if len(self._buffer) < size:
                break
            packages.append(RtdePackage(package_type, bytes(self._buffer[HEADER_SIZE:size])))
            del self._buffer[:size]
        return packages

    @property
    def pending_bytes(self) -> int:
        """Bytes held back waiting for the rest of a package."""
        return len(self._buffer)


# ---- helpers --------------------------------------------------------------------------------------------------


def _expect_size(payload: bytes, size: int, what: str) -> None:
    if len(payload) != size:
        raise ProtocolError(f"RTDE {what}: expected {size} payload bytes, got {len(payload)}")


def _decode_text(payload: bytes, what: str) -> str:
    try:
        return payload.decode("ascii")
    except UnicodeDecodeError as exc:
        raise ProtocolError(f"RTDE {what}: names are not ASCII") from exc


def _split_names(text: str) -> tuple[str, ...]:
    """Comma-joined list -> names; a trailing comma (ur_rtde sends one) adds no empty name."""
    return tuple(name for name in text.split(",") if name)


def _single_flag(payload: bytes, what: str) -> bool:
    _expect_size(payload, 1, what)
    return payload[0] != 0


# ---- V: protocol version ------------------------------------------------------------------------------------


def encode_request_protocol_version(version: int = PROTOCOL_VERSION) -> bytes:
    return encode_package(PackageType.REQUEST_PROTOCOL_VERSION, struct.pack(">H", version))


def decode_request_protocol_version(payload: bytes) -> int:
    _expect_size(payload, 2, "protocol version request")
    return int(struct.unpack(">H", payload)[0])


def encode_protocol_version_reply(accepted: bool) -> bytes:
    return encode_package(PackageType.REQUEST_PROTOCOL_VERSION, bytes([1 if accepted else 0]))


def decode_protocol_version_reply(payload: bytes) -> bool:
    return _single_flag(payload, "protocol version reply")


# ---- v: controller version ----------------------------------------------------------------------------------


def encode_get_controller_version() -> bytes:
    return encode_package(PackageType.GET_URCONTROL_VERSION)


def encode_controller_version_reply(version: ControllerVersion) -> bytes:
    payload = struct.pack(">4I", version.major, version.minor, version.bugfix, version.build)
    return encode_package(PackageType.GET_URCONTROL_VERSION, payload)


def decode_controller_version_reply(payload: bytes) -> ControllerVersion:
    _expect_size(payload, 16, "controller version reply")
    major, minor, bugfix, build = struct.unpack(">4I", payload)
    return ControllerVersion(major, minor, bugfix, build)


# ---- O / I: recipes -----------------------------------------------------------------------------------------


def encode_setup_outputs(frequency_hz: float, names: Sequence[str], *, trailing_comma: bool = False) -> bytes:
    """Output recipe request; ``trailing_comma`` reproduces what ur_rtde sends."""
    text = ",".join(names) + ("," if trailing_comma else "")
    return encode_package(
        PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS, struct.pack(">d", frequency_hz) + text.encode("ascii")
    )


def decode_setup_outputs(payload: bytes) -> tuple[float, tuple[str, ...]]:
    """-> (frequency in Hz, variable names)."""
    if len(payload) < 8:
        raise ProtocolError(f"RTDE setup outputs: {len(payload)} bytes cannot hold the float64 frequency")
    (frequency_hz,) = struct.unpack_from(">d", payload)
    return float(frequency_hz), _split_names(_decode_text(payload[8:], "setup outputs"))


def encode_setup_inputs(names: Sequence[str]) -> bytes:
    return encode_package(PackageType.CONTROL_PACKAGE_SETUP_INPUTS, ",".join(names).encode("ascii"))


def decode_setup_inputs(payload: bytes) -> tuple[str, ...]:
    return _split_names(_decode_text(payload, "setup inputs"))


def encode_recipe_reply(package_type: int, reply: RecipeReply) -> bytes:
    """Reply to ``O`` or ``I`` (pass the request's type byte)."""
    if not 0 <= reply.recipe_id <= 255:
        raise ProtocolError(f"RTDE recipe id {reply.recipe_id} does not fit a uint8")
    return encode_package(package_type, bytes([reply.recipe_id]) + ",".join(reply.types).encode("ascii"))


def decode_recipe_reply(payload: bytes) -> RecipeReply:
    if not payload:
        raise ProtocolError("RTDE recipe reply is empty")
    return RecipeReply(payload[0], _split_names(_decode_text(payload[1:], "recipe reply")))


# ---- S / P: start and pause ---------------------------------------------------------------------------------


def encode_start() -> bytes:
    return encode_package(PackageType.CONTROL_PACKAGE_START)


def encode_pause() -> bytes:
    return encode_package(PackageType.CONTROL_PACKAGE_PAUSE)


def encode_accepted_reply(package_type: int, accepted: bool) -> bytes:
    """Reply to ``S`` or ``P``."""
    return encode_package(package_type, bytes([1 if accepted else 0]))


def decode_accepted_reply(payload: bytes) -> bool:
    return _single_flag(payload, "start/pause reply")


# ---- U: data packages ---------------------------------------------------------------------------------------


def recipe_struct(types: Sequence[str]) -> struct.Struct:
    """The big-endian layout of a data package's fields (recipe id excluded)."""
    try:
        return struct.Struct(">" + "".join(FIELD_FORMATS[t] for t in types))
    except KeyError as exc:
        raise ProtocolError(f"RTDE type {exc.args[0]!r} has no wire layout") from exc


def _flatten(types: Sequence[str], values: Sequence[FieldValue]) -> list[float | int | bool]:
    """One number per struct slot (vectors spread out); ``types`` already checked by :func:`recipe_struct`."""
    if len(types) != len(values):
        raise ProtocolError(f"RTDE data package: {len(values)} values for a recipe of {len(types)} fields")
    flat: list[float | int | bool] = []
    for field_type, value in zip(types, values, strict=True):
        count = _FIELD_COUNTS[field_type]
        if isinstance(value, tuple | list):
            if count > 1 and len(value) == count:
                flat.extend(value)
                continue
        elif count == 1:
            flat.append(value)
            continue
        raise ProtocolError(f"RTDE {field_type} needs {count} number(s), got {value!r}")
    return flat


def encode_data_package(recipe_id: int, types: Sequence[str], values: Sequence[FieldValue]) -> bytes:
    """Pack one ``U`` package for a recipe; vectors are sequences, scalars numbers."""
    layout = recipe_struct(types)
    try:
        body = layout.pack(*_flatten(types, values))
    except struct.error as exc:
        raise ProtocolError(f"RTDE data package values do not fit their types: {exc}") from exc
    return encode_package(PackageType.DATA_PACKAGE, bytes([recipe_id]) + body)


def decode_data_package(payload: bytes, types: Sequence[str]) -> tuple[int, list[FieldValue]]:
    """-> (recipe id, one value per field: float/int/bool, tuples for vectors)."""
    layout = recipe_struct(types)
    if len(payload) != 1 + layout.size:
        raise ProtocolError(f"RTDE data package: {len(payload) - 1} field bytes for a recipe of {layout.size} bytes")
    flat = layout.unpack_from(payload, 1)
    values: list[FieldValue] = []
    index = 0
    for field_type in types:
        count = _FIELD_COUNTS[field_type]
        values.append(tuple(flat[index : index + count]) if count > 1 else flat[index])
        index += count
    return payload[0], values


# ---- M: text messages ---------------------------------------------------------------------------------------


def encode_text_message(message: TextMessage) -> bytes:
    text = message.message.encode("utf-8")
    source = message.source.encode("utf-8")
    if len(text) > 255 or len(source) > 255 or not 0 <= message.warning_level <= 255:
        raise ProtocolError("RTDE text message: message/source longer than 255 bytes or bad level")
    payload = bytes([len(text)]) + text + bytes([len(source)]) + source + bytes([message.warning_level])
    return encode_package(PackageType.TEXT_MESSAGE, payload)


def decode_text_message(payload: bytes) -> TextMessage:
    try:
        text_len = payload[0]
        text = payload[1 : 1 + text_len]
        source_len = payload[1 + text_len]
        source = payload[2 + text_len : 2 + text_len + source_len]
        level_index = 2 + text_len + source_len
        level = payload[level_index]
    except IndexError as exc:
        raise ProtocolError("RTDE text message is shorter than its length fields say") from exc
    if len(payload) != level_index + 1 or len(text) != text_len or len(source) != source_len:
        raise ProtocolError("RTDE text message length fields do not match its size")
    return TextMessage(text.decode("utf-8", "replace"), source.decode("utf-8", "replace"), level)

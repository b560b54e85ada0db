"""xela_server (v1.7.x / 1.8.x) WebSocket JSON messages: the welcome and the per-broadcast sensor data.

Wire format (one JSON object per WebSocket text message, plain ``ws://<ip>:5000``):

* The first message after connecting is a welcome, ``{"message": "Welcome", ...}`` (v1.8 also tags messages with a
  ``"type"``: ``"welcome"`` / ``"routine"``). Clients skip it.
* Every data broadcast is ``{"message": <int sequence number, monotonic>, "time": <server Unix time, float s>,
  "sensors": <count>, ["type": "routine",] "1": {...}, "2": {...}}``: one key per sensor number, as a string.
* Each sensor object has ``"sensor"`` (its number, usually a string), ``"model"`` (e.g. ``"uSPa46"``, ``"uSPa44"``,
  ``"XR1944"``), ``"taxels"`` (24 for a 4x6), and ``"data"``: the raw counts, 3 per taxel in order X, Y, Z, taxels
  from the top left, line by line. ``data`` is a comma-separated string of 4-hex-digit uint16 values up to v1.7.6
  and a JSON list of ints from v1.7.7; both are accepted. ``"calibrated"`` is ``null`` or a flat list of
  3 * taxels floats in newtons (only when the server's force calibration is on). Optional per-sensor keys seen in
  the wild (``time``, ``temp``, ``ups``, ``extradots``) are kept verbatim in ``extra``.

Sources: mcsix/xela_server_ros readme and scripts/xela_service (v1.7.6), a lerobot fork's XELA plan, the
penn-figueroa-lab/xela_setup example (v1.8.0, ``calibrated`` reshaped to 4x6x3), omron-sinicx/xela_server_ros
notes/websocket-data-structure.md (hex string vs int list), as summarised in the project's hardware facts (section
1.3) and anchor survey (section 4.1). Pure codec: no I/O.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, TypeGuard

import numpy as np

from protocols.errors import ProtocolError
from protocols.xela_can import MAX_COUNT  # the uSkin's counts, unsigned 16-bit on either wire

# ASCII only: int(..., 16) would also take "-FFF", "0x1F", "F_FF", "١٢"
HEX_DIGITS = frozenset("0123456789ABCDEFabcdef")
MAX_SEQ = 2**63 - 1  # the sequence number is stored as int64
# Server Unix time (s): non-negative, and small enough that microseconds stay exact in a float64 (2**53 us, the year
# 2255); beyond that, device_t_us (int64 us) could not be formed from it.
MAX_SERVER_TIME_S = 2**53 / 1e6
MAX_CALIBRATED_N = 1e6  # |force| per axis in N; far beyond any tactile sensor, small enough to stay finite in sums
_SENSOR_KNOWN_KEYS = frozenset({"sensor", "model", "taxels", "data", "calibrated"})
_HINT = "check the xela_server version (1.7.x/1.8.x expected) and that the client talks to xela_server"


@dataclass
class XelaWelcome:
    """The greeting xela_server sends first after a client connects; ``raw`` is the whole JSON object."""

    raw: dict[str, Any]


@dataclass(eq=False)
class XelaSensorData:
    """One sensor's reading in one broadcast.

    ``values``: (taxels, 3) int64 raw counts in layout order. ``calibrated``: (taxels, 3) float64 N or None.
    ``extra``: the other per-sensor keys (``time``, ``temp``, ``ups``, ``extradots``...), verbatim.
    """

    sensor_number: int
    model: str
    taxels: int
    values: np.ndarray
    calibrated: np.ndarray | None = None
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(eq=False)
class XelaDataMessage:
    """One broadcast: server sequence number, server Unix time (s) and each sensor's data by sensor number."""

    seq: int
    server_time_s: float
    sensors: dict[int, XelaSensorData]
    msg_type: str | None = None


def _fail(reason: str) -> ProtocolError:
    return ProtocolError(f"malformed xela_server message: {reason}", hint=_HINT)


def _short(value: object) -> str:
    """repr for an error message, cut short (a 4,000-digit int or a long string stays readable)."""
    text = (
        repr(value) if not isinstance(value, int) or abs(value) < 10**30 else f"<int of {len(str(abs(value)))} digits>"
    )
    return text if len(text) <= 40 else text[:37] + "..."


def _is_int(value: object) -> TypeGuard[int]:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: object) -> TypeGuard[int | float]:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _decode_counts(raw: object, key: str, taxels: int) -> np.ndarray:
    """``data`` as a (taxels, 3) int64 array, from a hex string or a list of ints."""
    if isinstance(raw, str):
        tokens = raw.split(",") if raw.strip() else []
        counts: list[int] = []
        for position, token in enumerate(tokens):
            if len(token) != 4:
                raise _fail(f"sensor {key}: data item {position} {token[:12]!r} is not a 4-hex-digit count")
            if not HEX_DIGITS.issuperset(token):
                raise _fail(f"sensor {key}: data item {position} {token!r} is not hexadecimal")
            counts.append(int(token, 16))
    elif isinstance(raw, list):
        for position, item in enumerate(raw):
            if not _is_int(item) or not 0 <= item <= MAX_COUNT:
                raise _fail(f"sensor {key}: data item {position} {_short(item)} is not an integer count 0..65535")
        counts = raw
    else:
        raise _fail(f"sensor {key}: 'data' is {type(raw).__name__}, expected a hex string or a list of ints")
    if len(counts) != 3 * taxels:
        raise _fail(f"sensor {key}: 'data' has {len(counts)} values, expected 3 x {taxels} taxels = {3 * taxels}")
    return np.array(counts, dtype=np.int64).reshape(taxels, 3)


def _decode_calibrated(raw: object, key: str, taxels: int) -> np.ndarray | None:
    if raw is None:
        return None
    if not isinstance(raw, list):
        raise _fail(f"sensor {key}: 'calibrated' is {type(raw).__name__}, expected null or a list of numbers")
    if len(raw) != 3 * taxels:
        raise _fail(f"sensor {key}: 'calibrated' has {len(raw)} values, expected {3 * taxels}")
    for position, item in enumerate(raw):
        # compared as given: a huge int never becomes a float (OverflowError), NaN and inf fail the comparison
        if not _is_number(item) or not -MAX_CALIBRATED_N <= item <= MAX_CALIBRATED_N:
            raise _fail(f"sensor {key}: calibrated item {position} {_short(item)} is not a force in N")
    return np.array(raw, dtype=np.float64).reshape(taxels, 3)


def _decode_sensor(key: str, obj: object) -> XelaSensorData:
    if not isinstance(obj, dict):
        raise _fail(f"sensor {key} is {type(obj).__name__}, expected an object")
    for required in ("model", "taxels", "data"):
        if required not in obj:
            raise _fail(f"sensor {key} has no {required!r}")
    model = obj["model"]
    if not isinstance(model, str):
        raise _fail(f"sensor {key}: 'model' is {_short(model)}, expected a string")
    taxels = obj["taxels"]
    if not _is_int(taxels) or taxels <= 0:
        raise _fail(f"sensor {key}: 'taxels' is {_short(taxels)}, expected a positive int")
    if "sensor" in obj and str(obj["sensor"]) != key:
        raise _fail(f"sensor under key {key!r} calls itself sensor {_short(obj['sensor'])}")
    return XelaSensorData(
        sensor_number=int(key),
        model=model,
        taxels=taxels,
        values=_decode_counts(obj["data"], key, taxels),
        calibrated=_decode_calibrated(obj.get("calibrated"), key, taxels),
        extra={k: v for k, v in obj.items() if k not in _SENSOR_KNOWN_KEYS},
    )


def decode_message(text: str | bytes) -> XelaWelcome | XelaDataMessage:
    """Decode one WebSocket message from xela_server.

    Raises ProtocolError naming the first problem: not JSON, not an object, a missing/ill-typed field, a ``data``
    length that is not 3 x ``taxels``, a count outside 0..65535, or a ``sensors`` count that disagrees with the
    sensor keys present.
    """
    if isinstance(text, bytes | bytearray | memoryview):
        try:
            text = bytes(text).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise _fail(f"not UTF-8 text ({exc.reason} at byte {exc.start})") from exc
    try:
        obj = json.loads(text)
    except (ValueError, RecursionError) as exc:  # JSONDecodeError is a ValueError
        raise _fail(f"not JSON ({exc})") from exc
    if not isinstance(obj, dict):
        raise _fail(f"top level is {type(obj).__name__}, expected an object")
    message = obj.get("message")
    msg_type = obj.get("type")
    if msg_type is not None and not isinstance(msg_type, str):
        raise _fail(f"'type' is {msg_type!r}, expected a string")
    if isinstance(message, str) or msg_type == "welcome":
        return XelaWelcome(raw=obj)
    if message is None:
        raise _fail("no 'message' field (expected a sequence number or 'Welcome')")
    if not _is_int(message) or not 0 <= message <= MAX_SEQ:
        raise _fail(f"'message' is {_short(message)}, expected an int sequence number 0..2**63-1")
    server_time = obj.get("time")
    # compared as given: a huge int never becomes a float (OverflowError), NaN and inf fail the comparison
    if not _is_number(server_time) or not 0 <= server_time <= MAX_SERVER_TIME_S:
        raise _fail(f"'time' is {_short(server_time)}, expected server Unix time in s (0..{MAX_SERVER_TIME_S:.0f})")
    sensors: dict[int, XelaSensorData] = {}
    for key, value in obj.items():
        if key.isdigit() and key.isascii():
            if len(key) > 6:
                raise _fail(f"sensor key {key[:12]!r}... is not a plausible sensor number")
            sensor = _decode_sensor(key, value)
            if sensor.sensor_number in sensors:
                raise _fail(f"sensor number {sensor.sensor_number} appears under two keys")
            sensors[sensor.sensor_number] = sensor
    declared = obj.get("sensors", len(sensors))
    if not _is_int(declared) or declared != len(sensors):
        raise _fail(f"'sensors' says {_short(declared)} but {len(sensors)} sensor objects are present")
    return XelaDataMessage(seq=message, server_time_s=float(server_time), sensors=sensors, msg_type=msg_type)


def encode_welcome(msg_type: str | None = "welcome", **fields: Any) -> str:
    """The greeting a simulated xela_server sends first: ``{"message": "Welcome", ...fields}``."""
    obj: dict[str, Any] = {"message": "Welcome"}
    if msg_type is not None:
        obj["type"] = msg_type
    obj.update(fields)
    return json.dumps(obj)


def encode_data_message(
    seq: int,
    server_time_s: float,
    sensors: list[XelaSensorData],
    as_hex: bool = True,
    msg_type: str | None = "routine",
) -> str:
    """One data broadcast as xela_server writes it; ``as_hex`` picks the <=1.7.6 hex string over the int list."""
    obj: dict[str, Any] = {"message": seq, "time": server_time_s, "sensors": len(sensors)}
    if msg_type is not None:
        obj["type"] = msg_type
    for sensor in sensors:
        key = str(sensor.sensor_number)
        values = np.asarray(sensor.values)
        cal = None if sensor.calibrated is None else np.asarray(sensor.calibrated, dtype=np.float64)
        for what, array in (("values", values), ("calibrated", cal)):
            if array is not None and array.shape != (sensor.taxels, 3):
                raise ProtocolError(
                    f"sensor {key}: {what} shape {array.shape} != ({sensor.taxels}, 3)",
                    hint="pass one (X, Y, Z) row per taxel: raw counts, and forces in N (or None) for calibrated",
                )
        if values.size and (values.min() < 0 or values.max() > MAX_COUNT):
            raise ProtocolError(
                f"sensor {key}: counts must be within 0..65535",
                hint="clip raw counts to the 16-bit range before encoding",
            )
        if key in obj:
            raise ProtocolError(f"sensor number {key} appears twice", hint="give each sensor its own number")
        counts = [int(v) for v in values.reshape(-1)]
        obj[key] = {
            **sensor.extra,
            "sensor": key,
            "model": sensor.model,
            "taxels": sensor.taxels,
            "data": ",".join(f"{v:04X}" for v in counts) if as_hex else counts,
            "calibrated": None if cal is None else [float(v) for v in cal.reshape(-1)],
        }
    return json.dumps(obj)

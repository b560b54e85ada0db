"""xela_server JSON codec: messages written out by hand (hex string and int list forms), round trips, rejections."""

from __future__ import annotations

import contextlib
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols.errors import ProtocolError
from protocols.xela_ws import (
    MAX_SERVER_TIME_S,
    XelaDataMessage,
    XelaSensorData,
    XelaWelcome,
    decode_message,
    encode_data_message,
    encode_welcome,
)

# A 2-taxel sensor as xela_server <= 1.7.6 writes it: counts as 4-hex-digit strings, X Y Z per taxel.
HEX_MESSAGE = (
    '{"message": 42, "time": 1700000000.25, "sensors": 1, '
    '"1": {"sensor": "1", "model": "uSPa46", "taxels": 2, '
    '"data": "4010,8020,9030,0001,FFFF,0000", "calibrated": null}}'
)
# The same reading as 1.7.7+ writes it (int list), with v1.8's "type" and calibrated newtons.
LIST_MESSAGE = (
    '{"message": 43, "time": 1700000000.26, "sensors": 1, "type": "routine", '
    '"1": {"sensor": "1", "model": "uSPa46", "taxels": 2, "time": 1700000000.259, "temp": 31.5, '
    '"data": [16400, 32800, 36912, 1, 65535, 0], "calibrated": [-0.13, -0.1, 5.4, 0.0, 0.25, 0.5]}}'
)


def test_hex_string_data_decodes_to_counts_per_taxel() -> None:
    message = decode_message(HEX_MESSAGE)
    assert isinstance(message, XelaDataMessage)
    assert message.seq == 42
    assert message.server_time_s == 1700000000.25
    assert message.msg_type is None
    sensor = message.sensors[1]
    assert (sensor.sensor_number, sensor.model, sensor.taxels) == (1, "uSPa46", 2)
    assert sensor.values.tolist() == [[0x4010, 0x8020, 0x9030], [1, 0xFFFF, 0]]
    assert sensor.calibrated is None


def test_int_list_data_and_calibrated_newtons_decode() -> None:
    message = decode_message(LIST_MESSAGE.encode("utf-8"))
    assert isinstance(message, XelaDataMessage)
    assert message.msg_type == "routine"
    sensor = message.sensors[1]
    assert sensor.values.tolist() == [[16400, 32800, 36912], [1, 65535, 0]]
    assert sensor.calibrated is not None
    assert sensor.calibrated.tolist() == [[-0.13, -0.1, 5.4], [0.0, 0.25, 0.5]]
    assert sensor.extra == {"time": 1700000000.259, "temp": 31.5}


def test_welcome_is_recognised_in_both_versions() -> None:
    assert isinstance(decode_message('{"message": "Welcome", "version": "1.7.6"}'), XelaWelcome)
    welcome = decode_message(encode_welcome(version="1.8.0"))
    assert isinstance(welcome, XelaWelcome)
    assert welcome.raw == {"message": "Welcome", "type": "welcome", "version": "1.8.0"}


@pytest.mark.parametrize("as_hex", [True, False])
def test_round_trip_two_sensors(as_hex: bool) -> None:
    rng = np.random.default_rng(7)
    sensors = [
        XelaSensorData(1, "uSPa46", 24, rng.integers(0, 65536, size=(24, 3)), None),
        XelaSensorData(2, "uSPa44", 16, rng.integers(0, 65536, size=(16, 3)), rng.normal(size=(16, 3))),
    ]
    text = encode_data_message(9, 12.5, sensors, as_hex=as_hex)
    raw = json.loads(text)
    assert raw["sensors"] == 2 and raw["type"] == "routine"
    assert isinstance(raw["1"]["data"], str if as_hex else list)
    message = decode_message(text)
    assert isinstance(message, XelaDataMessage)
    assert (message.seq, message.server_time_s) == (9, 12.5)
    for original in sensors:
        decoded = message.sensors[original.sensor_number]
        assert decoded.model == original.model
        np.testing.assert_array_equal(decoded.values, original.values)
        if original.calibrated is None:
            assert decoded.calibrated is None
        else:
            np.testing.assert_array_equal(decoded.calibrated, original.calibrated)


def test_hex_encoding_is_four_upper_case_digits() -> None:
    text = encode_data_message(1, 0.0, [XelaSensorData(1, "uSPa46", 1, np.array([[0xFA00, 0x0A, 0]]))])
    assert json.loads(text)["1"]["data"] == "FA00,000A,0000"


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("{not json", "not JSON"),
        ("[1, 2]", "top level is list"),
        ('{"time": 1.0, "sensors": 0}', "no 'message'"),
        ('{"message": true, "time": 1.0, "sensors": 0}', "'message' is True"),
        ('{"message": 1, "sensors": 0}', "'time'"),
        (
            '{"message": 1, "time": 1.0, "sensors": 2, "1": ' + HEX_MESSAGE[HEX_MESSAGE.index('{"sensor"') : -1] + "}",
            "'sensors' says 2",
        ),
        ('{"message": 1, "time": 1.0, "1": {"model": "m", "taxels": 2, "data": "0001,0002"}}', "has 2 values"),
        ('{"message": 1, "time": 1.0, "1": {"model": "m", "taxels": 1, "data": "0001,ZZZZ,0003"}}', "not hexadecimal"),
        ('{"message": 1, "time": 1.0, "1": {"model": "m", "taxels": 1, "data": "0001,12345,0003"}}', "4-hex-digit"),
        ('{"message": 1, "time": 1.0, "1": {"model": "m", "taxels": 1, "data": [1, 2, 65536]}}', "0..65535"),
        (
            '{"message": 1, "time": 1.0, "1": {"model": "m", "taxels": 1, "data": [1, 2, 3], "calibrated": [1]}}',
            "'calibrated' has 1 values",
        ),
        ('{"message": 1, "time": 1.0, "1": {"model": "m", "data": [1, 2, 3]}}', "no 'taxels'"),
        (
            '{"message": 1, "time": 1.0, "1": {"sensor": "2", "model": "m", "taxels": 1, "data": [1, 2, 3]}}',
            "calls itself sensor",
        ),
    ],
)
def test_malformed_messages_say_what_is_wrong(text: str, reason: str) -> None:
    with pytest.raises(ProtocolError) as info:
        decode_message(text)
    assert reason in str(info.value)
    assert info.value.hint


def test_non_utf8_bytes_raise_protocol_error() -> None:
    with pytest.raises(ProtocolError, match="UTF-8"):
        decode_message(b"\xff\xfe{")


def test_encoder_refuses_counts_outside_16_bits() -> None:
    with pytest.raises(ProtocolError):
        encode_data_message(1, 0.0, [XelaSensorData(1, "uSPa46", 1, np.array([[0, 0, 70_000]]))])


_json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=4), children, max_size=4),
    max_leaves=20,
)


@settings(max_examples=150, deadline=None)
@given(st.one_of(st.text(max_size=200), st.binary(max_size=200)))
def test_arbitrary_text_only_ever_raises_protocol_error(text: str | bytes) -> None:
    with contextlib.suppress(ProtocolError):
        decode_message(text)


@settings(max_examples=150, deadline=None)
@given(
    st.dictionaries(
        st.sampled_from(["message", "time", "sensors", "type", "1", "2"]) | st.text(max_size=3), _json_values
    )
)
def test_arbitrary_json_objects_only_ever_raise_protocol_error(obj: dict) -> None:
    with contextlib.suppress(ProtocolError):
        decode_message(json.dumps(obj))


def _one_taxel(data: str, time_s: str = "1.5", message: str = "1", calibrated: str = "null") -> str:
    return (
        f'{{"message": {message}, "time": {time_s}, "1": {{"model": "m", "taxels": 1, "data": {data}, '
        f'"calibrated": {calibrated}}}}}'
    )


@pytest.mark.parametrize(
    "text",
    [
        _one_taxel('"0001,0002,0003"', time_s="1" + "0" * 400),  # raised OverflowError
        _one_taxel('"0001,0002,0003"', time_s="1e303"),  # passed, then crashed the driver
        _one_taxel('"0001,0002,0003"', time_s="NaN"),
        _one_taxel('"0001,0002,0003"', time_s="-Infinity"),
        _one_taxel('"0001,0002,0003"', time_s="-1"),
        _one_taxel('"0001,0002,0003"', message="-1"),
        _one_taxel('"0001,0002,0003"', message=str(2**64)),
        _one_taxel('"-FFF,0002,0003"'),  # was read as -4095
        _one_taxel('"0x1F,0002,0003"'),
        _one_taxel('"F_FF,0002,0003"'),
        _one_taxel('"\u0661\u0662\u0663\u0664,0002,0003"'),  # Arabic-Indic digits: int(..., 16) takes them
        _one_taxel('"+FFF,0002,0003"'),
        _one_taxel('" FFF,0002,0003"'),
        _one_taxel('"1,0002,0003"'),  # the facts say 4 hex digits
        _one_taxel("[1, 2, 65536]"),
        _one_taxel("[-1, 2, 3]"),
        _one_taxel("[1, 2, 3]", calibrated="[1e400, 0, 0]"),
        _one_taxel("[1, 2, 3]", calibrated="[NaN, 0, 0]"),
        _one_taxel("[1, 2, 3]", calibrated="[" + "9" * 400 + ", 0, 0]"),  # OverflowError converting to float
    ],
)
def test_values_outside_what_xela_server_sends_are_refused(text: str) -> None:
    """Issue 28: huge, non-finite or negative numbers and hex forms int() takes but xela_server never writes."""
    with pytest.raises(ProtocolError):
        decode_message(text)


@settings(max_examples=300, deadline=None)
@given(st.text(min_size=4, max_size=4))
def test_a_data_item_is_accepted_exactly_when_it_is_four_ascii_hex_digits(token: str) -> None:
    text = json.dumps({"message": 1, "time": 1.5, "1": {"model": "m", "taxels": 1, "data": f"{token},0000,FFFF"}})
    if all(c in "0123456789abcdefABCDEF" for c in token):
        (sensor,) = decode_message(text).sensors.values()  # type: ignore[union-attr]
        assert sensor.values[0].tolist() == [int(token, 16), 0, 0xFFFF]
    else:
        with pytest.raises(ProtocolError):
            decode_message(text)


@settings(max_examples=200, deadline=None)
@given(
    st.one_of(st.integers(), st.floats()),
    st.lists(st.one_of(st.integers(), st.floats()), min_size=3, max_size=3),
)
def test_accepted_messages_hold_only_finite_times_and_forces(time_s: float, calibrated: list[float]) -> None:
    text = json.dumps({"message": 1, "time": time_s, "1": {"model": "m", "taxels": 1, "data": [1, 2, 3],
                                                          "calibrated": calibrated}})  # fmt: skip
    try:
        message = decode_message(text)
    except ProtocolError:
        return
    assert isinstance(message, XelaDataMessage)
    assert 0 <= message.server_time_s <= MAX_SERVER_TIME_S
    round(message.server_time_s * 1e6)  # the driver's device_t_us: must not overflow
    sensor = message.sensors[1]
    assert sensor.calibrated is not None and np.isfinite(sensor.calibrated).all()

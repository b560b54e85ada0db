"""RTDE v2 codec: golden vectors worked by hand from the wire format, round trips, and a framer that survives splits."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocols import rtde
from protocols.errors import ProtocolError
from protocols.rtde import ControllerVersion, PackageType, RecipeReply, RtdePackage, TextMessage


def frame(data: bytes) -> RtdePackage:
    """Parse exactly one whole package."""
    parser = rtde.RtdePackageParser()
    packages = parser.feed(data)
    assert len(packages) == 1 and parser.pending_bytes == 0
    return packages[0]


# ---- golden vectors: header = uint16 size (incl. the 3 header bytes) + uint8 type, big-endian ---------------------


def test_protocol_version_request_is_size_5_type_V_version_2() -> None:
    assert rtde.encode_request_protocol_version() == b"\x00\x05V\x00\x02"
    assert rtde.decode_request_protocol_version(b"\x00\x02") == 2
    assert rtde.encode_protocol_version_reply(True) == b"\x00\x04V\x01"
    assert rtde.decode_protocol_version_reply(b"\x00") is False


def test_controller_version_reply_is_four_big_endian_uint32() -> None:
    data = rtde.encode_controller_version_reply(ControllerVersion(5, 11, 0, 108249))
    assert data == b"\x00\x13v" + bytes.fromhex("000000050000000b000000000001a6d9")
    assert rtde.decode_controller_version_reply(frame(data).payload) == ControllerVersion(5, 11, 0, 108249)
    assert rtde.encode_get_controller_version() == b"\x00\x03v"


def test_setup_outputs_carries_float64_frequency_and_names_with_ur_rtde_trailing_comma() -> None:
    data = rtde.encode_setup_outputs(500.0, ["timestamp"], trailing_comma=True)
    # 500.0 = 0x407F400000000000; payload 8 + len("timestamp,") = 18 bytes, size 21 = 0x15
    assert data == b"\x00\x15O" + bytes.fromhex("407f400000000000") + b"timestamp,"
    assert rtde.decode_setup_outputs(frame(data).payload) == (500.0, ("timestamp",))


def test_recipe_reply_has_id_then_types_and_flags_not_found() -> None:
    data = rtde.encode_recipe_reply(PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS, RecipeReply(1, ("DOUBLE", "NOT_FOUND")))
    assert data == b"\x00\x14O\x01DOUBLE,NOT_FOUND"  # 3 + 1 + len("DOUBLE,NOT_FOUND") = 20
    reply = rtde.decode_recipe_reply(frame(data).payload)
    assert reply == RecipeReply(1, ("DOUBLE", "NOT_FOUND"))
    assert not reply.ok
    assert RecipeReply(2, ("INT32",)).ok


def test_setup_inputs_and_in_use_reply() -> None:
    assert rtde.encode_setup_inputs(["input_int_register_0"]) == b"\x00\x17Iinput_int_register_0"
    reply = rtde.decode_recipe_reply(b"\x00IN_USE")
    assert reply.types == ("IN_USE",) and not reply.ok


def test_start_and_pause_are_bare_headers_with_one_byte_replies() -> None:
    assert rtde.encode_start() == b"\x00\x03S"
    assert rtde.encode_pause() == b"\x00\x03P"
    assert rtde.encode_accepted_reply(PackageType.CONTROL_PACKAGE_START, True) == b"\x00\x04S\x01"
    assert rtde.decode_accepted_reply(b"\x01") is True


def test_data_package_packs_fields_back_to_back() -> None:
    data = rtde.encode_data_package(1, ["DOUBLE", "INT32", "UINT32"], [1.0, 7, 4])
    # recipe 1, 1.0 = 0x3FF0000000000000, int32 7, uint32 4 (protective-stop bit): payload 17, size 20
    assert data == b"\x00\x14U\x01" + bytes.fromhex("3ff00000000000000000000700000004")
    assert rtde.decode_data_package(frame(data).payload, ["DOUBLE", "INT32", "UINT32"]) == (1, [1.0, 7, 4])


def test_vector6d_is_48_bytes_and_decodes_to_a_tuple() -> None:
    pose = (0.1, -0.2, 0.3, 0.0, 3.14, -1.5)
    data = rtde.encode_data_package(3, ["VECTOR6D"], [pose])
    assert len(data) == 3 + 1 + 48
    assert data[4:] == struct.pack(">6d", *pose)
    assert rtde.decode_data_package(data[3:], ["VECTOR6D"]) == (3, [pose])


def test_text_message_v2_layout() -> None:
    data = rtde.encode_text_message(TextMessage("hi", "ur", 1))
    assert data == b"\x00\x0aM\x02hi\x02ur\x01"
    assert rtde.decode_text_message(frame(data).payload) == TextMessage("hi", "ur", 1)


# ---- type table ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("timestamp", "DOUBLE"),
        ("actual_TCP_pose", "VECTOR6D"),
        ("actual_TCP_force", "VECTOR6D"),
        ("actual_q", "VECTOR6D"),
        ("robot_mode", "INT32"),
        ("safety_mode", "INT32"),
        ("safety_status_bits", "UINT32"),
        ("runtime_state", "UINT32"),
        ("output_int_register_12", "INT32"),
        ("output_double_register_19", "DOUBLE"),
        ("input_double_register_17", "DOUBLE"),
        ("output_int_register_48", None),
        ("output_bit_register_64", "BOOL"),
        ("output_bit_register_3", None),
        ("no_such_thing", None),
    ],
)
def test_variable_types(name: str, expected: str | None) -> None:
    assert rtde.variable_type(name) == expected


# ---- errors ----------------------------------------------------------------------------------------------------


def test_wrong_payload_sizes_and_values_raise_protocol_error() -> None:
    with pytest.raises(ProtocolError):
        rtde.decode_controller_version_reply(b"\x00" * 15)
    with pytest.raises(ProtocolError):
        rtde.decode_data_package(b"\x01\x00", ["DOUBLE"])
    with pytest.raises(ProtocolError):
        rtde.encode_data_package(1, ["VECTOR6D"], [(1.0, 2.0)])
    with pytest.raises(ProtocolError):
        rtde.encode_data_package(1, ["INT32"], [(1, 2)])
    with pytest.raises(ProtocolError):
        rtde.encode_data_package(1, ["QUATERNION"], [0])
    with pytest.raises(ProtocolError):
        rtde.decode_text_message(b"\x05hi")
    with pytest.raises(ProtocolError):
        rtde.decode_setup_outputs(b"\x00\x01")


# ---- the framer --------------------------------------------------------------------------------------------------


STREAM = (
    rtde.encode_request_protocol_version()
    + rtde.encode_setup_outputs(125.0, ["timestamp", "actual_TCP_pose"], trailing_comma=True)
    + rtde.encode_start()
    + rtde.encode_data_package(1, ["DOUBLE", "VECTOR6D"], [2.5, (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)])
)


def test_byte_by_byte_feed_gives_the_same_packages_as_one_chunk() -> None:
    whole = rtde.RtdePackageParser().feed(STREAM)
    parser = rtde.RtdePackageParser()
    pieces = [package for byte in STREAM for package in parser.feed(bytes([byte]))]
    assert pieces == whole
    assert [p.type for p in whole] == [ord("V"), ord("O"), ord("S"), ord("U")]
    assert parser.dropped_bytes == 0


def test_garbage_before_a_package_is_dropped_and_counted() -> None:
    parser = rtde.RtdePackageParser()
    # 0x00 0x00 is an impossible size, 0xff an unknown type: each is skipped one byte at a time
    packages = parser.feed(b"\x00\x00\xff" + rtde.encode_start())
    assert packages == [RtdePackage(ord("S"), b"")]
    assert parser.dropped_bytes == 3


@given(
    chunks=st.lists(st.integers(min_value=1, max_value=40), min_size=1, max_size=60),
)
def test_any_split_of_a_stream_parses_identically(chunks: list[int]) -> None:
    parser = rtde.RtdePackageParser()
    out: list[RtdePackage] = []
    position = 0
    for size in chunks:
        out += parser.feed(STREAM[position : position + size])
        position += size
    out += parser.feed(STREAM[position:])
    assert out == rtde.RtdePackageParser().feed(STREAM)


_FIELD = st.sampled_from(sorted(rtde.FIELD_FORMATS))


def _value_for(field_type: str) -> st.SearchStrategy[object]:
    finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
    scalars: dict[str, st.SearchStrategy[object]] = {
        "BOOL": st.booleans(),
        "UINT8": st.integers(0, 255),
        "INT32": st.integers(-(2**31), 2**31 - 1),
        "UINT32": st.integers(0, 2**32 - 1),
        "UINT64": st.integers(0, 2**64 - 1),
        "DOUBLE": finite,
        "VECTOR3D": st.tuples(finite, finite, finite),
        "VECTOR6D": st.tuples(*[finite] * 6),
        "VECTOR6INT32": st.tuples(*[st.integers(-(2**31), 2**31 - 1)] * 6),
        "VECTOR6UINT32": st.tuples(*[st.integers(0, 2**32 - 1)] * 6),
    }
    return scalars[field_type]


@given(data=st.data(), types=st.lists(_FIELD, min_size=1, max_size=12), recipe_id=st.integers(0, 255))
def test_data_package_round_trip(data: st.DataObject, types: list[str], recipe_id: int) -> None:
    values = [data.draw(_value_for(t)) for t in types]
    encoded = rtde.encode_data_package(recipe_id, types, values)  # type: ignore[arg-type]
    assert rtde.decode_data_package(frame(encoded).payload, types) == (recipe_id, values)


_NAME = st.text(alphabet=st.characters(min_codepoint=ord("a"), max_codepoint=ord("z")) | st.just("_"), min_size=1)


@given(frequency=st.floats(0.1, 500.0), names=st.lists(_NAME, min_size=1, max_size=10), comma=st.booleans())
def test_setup_outputs_round_trip(frequency: float, names: list[str], comma: bool) -> None:
    encoded = rtde.encode_setup_outputs(frequency, names, trailing_comma=comma)
    assert rtde.decode_setup_outputs(frame(encoded).payload) == (frequency, tuple(names))


@given(garbage=st.binary(max_size=64))
def test_parser_never_raises_and_keeps_at_most_one_partial_package(garbage: bytes) -> None:
    parser = rtde.RtdePackageParser()
    packages = parser.feed(garbage)
    assert parser.dropped_bytes + sum(3 + len(p.payload) for p in packages) + parser.pending_bytes == len(garbage)

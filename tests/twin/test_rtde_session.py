"""The server side of an RTDE connection: recipe numbering as ur_rtde's control client needs it."""

from __future__ import annotations

from protocols import rtde
from protocols.rtde import ControllerVersion, PackageType
from unitac_rig.sim.twin.rtde_session import RtdeSession


def _reply(session: RtdeSession, request: bytes) -> rtde.RecipeReply:
    (package,) = rtde.RtdePackageParser().feed(request)
    reply = session.handle(package)
    assert reply is not None
    (answer,) = rtde.RtdePackageParser().feed(reply)
    return rtde.decode_recipe_reply(answer.payload)


def test_input_recipes_are_numbered_from_one_apart_from_the_output_recipe() -> None:
    """ur_rtde hard-codes input recipe ids 1, 2, 3... in setup order, after setting up its output recipe."""
    session = RtdeSession("test", controller_version=ControllerVersion(5, 11, 0, 0), max_frequency_hz=500.0)
    output = _reply(session, rtde.encode_setup_outputs(500.0, ["timestamp", "runtime_state"], trailing_comma=True))
    assert output.recipe_id == 1
    ids = [
        _reply(session, rtde.encode_setup_inputs(names)).recipe_id
        for names in (
            ["input_int_register_0", "input_double_register_0"],
            ["input_int_register_0", "no_such_input"],  # NOT_FOUND: refused, but its id is used up
            ["input_int_register_0"],
        )
    ]
    assert ids == [1, 2, 3]
    package = rtde.encode_data_package(3, ["INT32"], [35])
    (parsed,) = rtde.RtdePackageParser().feed(package)
    assert parsed.type == PackageType.DATA_PACKAGE
    assert session.input_values(parsed.payload) == {"input_int_register_0": 35}
    assert session.input_values(rtde.encode_data_package(2, ["INT32"], [1])[3:]) is None  # the refused recipe


def test_a_register_held_by_a_fieldbus_refuses_the_recipe() -> None:
    session = RtdeSession(
        "test",
        controller_version=ControllerVersion(5, 11, 0, 0),
        max_frequency_hz=500.0,
        registers_in_use=frozenset({"input_int_register_0"}),
    )
    reply = _reply(session, rtde.encode_setup_inputs(["input_int_register_0", "input_double_register_1"]))
    assert reply.types == (rtde.IN_USE, "DOUBLE") and reply.recipe_id == 0

"""The server side of one RTDE connection, without the socket: what the controller twin answers a ur_rtde client.

Recipes (``O``/``I``) typed from :mod:`protocols.rtde`'s table, which must agree with ur_rtde's own (the client
parses ``U`` packages with its table, not with the types in the ``O`` reply); start and pause; the stream schedule;
values by name, zeros for the variables the twin does not model (joint values, currents...) so a client may still
subscribe to them. Names nobody knows get ``NOT_FOUND``.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence

from protocols import rtde
from protocols.rtde import ControllerVersion, PackageType, RecipeReply

logger = logging.getLogger(__name__)


def _zero_value(field_type: str) -> rtde.FieldValue:
    if field_type == "VECTOR3D":
        return (0.0, 0.0, 0.0)
    if field_type == "VECTOR6D":
        return (0.0,) * 6
    if field_type in ("VECTOR6INT32", "VECTOR6UINT32"):
        return (0,) * 6
    if field_type == "DOUBLE":
        return 0.0
    if field_type == "BOOL":
        return False
    return 0


def values_for(
    names: Sequence[str], types: Sequence[str], known: Mapping[str, rtde.FieldValue]
) -> list[rtde.FieldValue]:
    """Values of an output recipe: from ``known`` by name, zeros for variables the simulation does not model."""
    return [known[name] if name in known else _zero_value(t) for name, t in zip(names, types, strict=True)]


# Input-only variables a controller accepts besides the registers (ur_rtde's setExternalForceTorque recipe).
INPUT_VARIABLE_TYPES: dict[str, str] = {"external_force_torque": "VECTOR6D"}


def input_variable_type(name: str) -> str:
    """RTDE type of an input (client -> controller) variable, or ``NOT_FOUND``."""
    if name in INPUT_VARIABLE_TYPES:
        return INPUT_VARIABLE_TYPES[name]
    known = rtde.variable_type(name) if name.startswith("input_") else None
    return known or rtde.NOT_FOUND


class RtdeSession:
    """The server side of one RTDE connection, without the socket: recipes, start/pause and the stream schedule.

    Output and input recipes are numbered 1, 2, 3... on **separate counters**: ur_rtde's control client hard-codes
    its input recipe ids 1..23 in setup order and ignores the ids in the replies, so one shared counter (output
    recipe = 1, inputs from 2) breaks it silently. Every input recipe request gets an id, even one with
    ``NOT_FOUND`` in it (the client ignores that reply and counts on the next id); one with ``IN_USE`` gets 0, as a
    controller refuses it.
    """

    def __init__(
        self,
        peer: str,
        *,
        controller_version: ControllerVersion,
        max_frequency_hz: float,
        registers_in_use: frozenset[str] = frozenset(),
        outputs_not_found: frozenset[str] = frozenset(),
    ) -> None:
        self.peer = peer
        self.controller_version = controller_version
        self.max_frequency_hz = max_frequency_hz
        self.registers_in_use = registers_in_use
        self.outputs_not_found = outputs_not_found  # output names answered NOT_FOUND (a controller without them)
        self.output_names: tuple[str, ...] = ()
        self.output_types: tuple[str, ...] = ()
        self.output_recipe_id = 0
        self.input_recipes: dict[int, tuple[tuple[str, ...], tuple[str, ...]]] = {}
        self._next_output_id = 1
        self._next_input_id = 1
        self.period_s = 1.0 / max_frequency_hz
        self.streaming = False
        self.next_due_s = 0.0

    @property
    def wants_data(self) -> bool:
        """Started and subscribed to something: data packages are due every ``period_s``."""
        return self.streaming and bool(self.output_types)

    def handle(self, package: rtde.RtdePackage) -> bytes | None:
        """The reply to a request package (None for data packages and text messages, which get none)."""
        kind = package.type
        if kind == PackageType.REQUEST_PROTOCOL_VERSION:
            version = rtde.decode_request_protocol_version(package.payload)
            return rtde.encode_protocol_version_reply(version == rtde.PROTOCOL_VERSION)
        if kind == PackageType.GET_URCONTROL_VERSION:
            return rtde.encode_controller_version_reply(self.controller_version)
        if kind == PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS:
            return self._setup_outputs(package.payload)
        if kind == PackageType.CONTROL_PACKAGE_SETUP_INPUTS:
            return self._setup_inputs(package.payload)
        if kind == PackageType.CONTROL_PACKAGE_START:
            self.streaming = True
            self.next_due_s = time.monotonic()
            return rtde.encode_accepted_reply(kind, True)
        if kind == PackageType.CONTROL_PACKAGE_PAUSE:
            self.streaming = False
            return rtde.encode_accepted_reply(kind, True)
        if kind == PackageType.TEXT_MESSAGE:
            message = rtde.decode_text_message(package.payload)
            logger.info("RTDE client %s says [%s] %s", self.peer, message.source, message.message)
        return None

    def input_values(self, payload: bytes) -> dict[str, rtde.FieldValue] | None:
        """The variables a data package from the client writes, by name; None for an unknown recipe id."""
        recipe_id = payload[0] if payload else -1
        recipe = self.input_recipes.get(recipe_id)
        if recipe is None:
            logger.debug("RTDE client %s sent data for unknown input recipe %d", self.peer, recipe_id)
            return None
        names, types = recipe
        _, values = rtde.decode_data_package(payload, types)
        return dict(zip(names, values, strict=True))

    def take_due(self, now_s: float) -> bool:
        """True (and the schedule moves on) when a data package is due at ``now_s``; never bursts to catch up."""
        if not self.wants_data or self.next_due_s > now_s:
            return False
        self.next_due_s += self.period_s
        if self.next_due_s < now_s - self.period_s:  # fell behind: skip, do not burst
            self.next_due_s = now_s + self.period_s
        return True

    def data_package(self, known: Mapping[str, rtde.FieldValue]) -> bytes:
        """One output data package, values by name from ``known`` (zeros for the rest)."""
        values = values_for(self.output_names, self.output_types, known)
        return rtde.encode_data_package(self.output_recipe_id, self.output_types, values)

    def _setup_outputs(self, payload: bytes) -> bytes:
        frequency_hz, names = rtde.decode_setup_outputs(payload)
        types = tuple(
            rtde.NOT_FOUND if name in self.outputs_not_found else rtde.variable_type(name) or rtde.NOT_FOUND
            for name in names
        )
        recipe_id = 0
        if names and rtde.NOT_FOUND not in types:
            limit_hz = self.max_frequency_hz
            if not 0 < frequency_hz <= limit_hz:  # NaN and inf too: never a stream period of NaN or 0 s
                logger.info("RTDE client %s asked for %.1f Hz; streaming at %.1f Hz", self.peer, frequency_hz, limit_hz)
                frequency_hz = limit_hz
            recipe_id = self._next_output_id
            self._next_output_id += 1
            self.output_names, self.output_types = names, types
            self.output_recipe_id = recipe_id
            self.period_s = 1.0 / frequency_hz
        return rtde.encode_recipe_reply(PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS, RecipeReply(recipe_id, types))

    def _setup_inputs(self, payload: bytes) -> bytes:
        names = rtde.decode_setup_inputs(payload)
        types = tuple(rtde.IN_USE if n in self.registers_in_use else input_variable_type(n) for n in names)
        recipe_id = 0
        if names and rtde.IN_USE not in types:
            recipe_id = self._next_input_id
            self._next_input_id += 1
            if rtde.NOT_FOUND not in types:
                self.input_recipes[recipe_id] = (names, types)
        return rtde.encode_recipe_reply(PackageType.CONTROL_PACKAGE_SETUP_INPUTS, RecipeReply(recipe_id, types))

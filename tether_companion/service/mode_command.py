"""A ground station's COMMAND_LONG to this component: the tension modes' run-time control.

A ground station addresses the companion (its system and component id) with
:data:`TENSION_MODE_COMMAND` to enable or disable the tension modes and to request or cancel a
tension-following landing. The answer is a COMMAND_ACK: ACCEPTED, DENIED (a sender outside
``security.command_sources``, an unsigned one with signing required, or parameters outside
the values below) or UNSUPPORTED (any other command), addressed to the command's sender (its
``target_system``/``target_component``, as MAVLink defines them, so that an autopilot routes
it back to that ground station only). Pure: the session hands it the message,
its security configuration and the modes.
"""

from __future__ import annotations

from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.modes.tension_following import TensionModes
from tether_companion.service.link_config import LinkConfig, SecurityConfig
from tether_companion.service.security import command_refusal

TENSION_MODE_COMMAND = dialect.MAV_CMD_USER_2
"""COMMAND_LONG a ground station sends to this component (our system and component id) to
control the tension modes at run time: param1 1 enable, 0 disable, -1 unchanged; param2 1
request a landing, 2 cancel it, 0 nothing. Answered with COMMAND_ACK (DENIED for other
values, UNSUPPORTED for other commands)."""


def addressed_to_us(msg: MAVLinkMessage, link: LinkConfig) -> bool:
    """Whether a COMMAND_LONG targets this component (``link.system_id`` and
    ``link.component_id``)."""
    return msg.target_system == link.system_id and msg.target_component == link.component_id


def answer_mode_command(
    msg: MAVLinkMessage,
    security: SecurityConfig,
    modes: TensionModes,
    refused: dict[str, int],
) -> MAVLinkMessage:
    """Carry out a ground station's COMMAND_LONG to this component and return its COMMAND_ACK.

    A command refused for its sender (:func:`~tether_companion.service.security.command_refusal`)
    is DENIED and counted in ``refused`` by reason; :data:`TENSION_MODE_COMMAND` with valid
    parameters changes ``modes`` and is ACCEPTED; any other command is UNSUPPORTED.
    """
    result = dialect.MAV_RESULT_UNSUPPORTED
    refusal = command_refusal(msg, security)
    if refusal is not None:
        refused[refusal] = refused.get(refusal, 0) + 1
        result = dialect.MAV_RESULT_DENIED
    elif msg.command == TENSION_MODE_COMMAND:
        enable, landing = msg.param1, msg.param2
        if enable not in (-1.0, 0.0, 1.0) or landing not in (0.0, 1.0, 2.0):
            result = dialect.MAV_RESULT_DENIED
        else:
            if enable >= 0.0:
                modes.set_enabled(enable == 1.0)
            if landing == 1.0:
                modes.request_landing()
            elif landing == 2.0:
                modes.cancel_landing()
            result = dialect.MAV_RESULT_ACCEPTED
    return dialect.MAVLink_command_ack_message(
        msg.command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
    )

"""``vehicle: from_autopilot``: read the vehicle's parameters from the flight controller.

The service asks for each parameter it needs by name (PARAM_REQUEST_READ, ``param_index`` -1)
and collects the PARAM_VALUE answers; a name not answered ``interval_s`` after the last of
``attempts`` requests ``interval_s`` apart counts as absent (ArduPilot does not answer unknown
names), and :func:`tether_companion.vehicle_params.profile.profile_from_parameters` then applies the
firmware default or refuses. For PX4 the rotor count comes first; the per-rotor and per-output
names follow from it. PX4 sends integer parameters bytewise, ArduPilot as a float value.
The fetch starts again after a flight-controller reboot. No I/O here: the service sends what
:meth:`VehicleFetch.requests` returns and passes PARAM_VALUE messages in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tether_companion.config import ConfigError, spec
from tether_companion.mavlink.framing import MAVLinkMessage, dialect
from tether_companion.vehicle_params import ardupilot, px4
from tether_companion.vehicle_params.sources import param_name, param_value

FROM_AUTOPILOT = "from_autopilot"
"""The ``vehicle:`` value that reads the profile from the flight controller."""


@dataclass(frozen=True)
class AutopilotVehicleConfig:
    """What ``vehicle: from_autopilot`` needs beyond the flight controller's parameters."""

    mass_kg: float | None = spec(
        None,
        exclusive_minimum=0.0,
        maximum=500.0,
        doc="take-off mass [kg] (required with vehicle: from_autopilot: no parameter holds it)",
    )
    fallback: str | None = spec(
        None,
        doc="profile used (with a STATUSTEXT saying why) when the parameters are missing or "
        "bad; null: the service stops with exit code 2 naming the parameter",
    )
    base: str = spec(
        "default-quad",
        doc="profile giving the keys the parameters do not (inertia, motor lag, drag)",
    )
    request_interval_s: float = spec(
        1.0, exclusive_minimum=0.0, maximum=30.0, doc="resend an unanswered request after [s]"
    )
    attempts: int = spec(3, minimum=1, maximum=20, doc="requests per name before it is absent")


def wanted_names(autopilot: str, known: dict[str, float]) -> list[str]:
    """The parameter names the profile needs, given those already known."""
    if autopilot != "px4":
        return list(ardupilot.PARAMETERS)
    names = ["CA_AIRFRAME", "CA_ROTOR_COUNT", "THR_MDL_FAC", "MPC_THR_HOVER"]
    count = known.get("CA_ROTOR_COUNT")
    if count is not None and math.isfinite(count) and 0 < count <= px4.MAX_ROTORS:
        n = int(count)
        for i in range(n):
            names += [f"CA_ROTOR{i}_PX", f"CA_ROTOR{i}_PY", f"CA_ROTOR{i}_KM"]
        for j in range(1, n + 1):
            names += [f"PWM_MAIN_MIN{j}", f"PWM_MAIN_MAX{j}", f"PWM_MAIN_FUNC{j}"]
    return names


class VehicleFetch:
    """Collects the vehicle's parameters with the parameter protocol (module docstring).

    Parameters
    ----------
    autopilot
        ``"ardupilot"`` or ``"px4"`` (the link's flavour).
    target_system, target_component
        The flight controller's ids.
    config
        Request interval and attempts.
    """

    def __init__(
        self,
        autopilot: str,
        target_system: int,
        target_component: int,
        config: AutopilotVehicleConfig,
    ) -> None:
        self.autopilot = autopilot
        self.target = (target_system, target_component)
        self.config = config
        self.params: dict[str, float] = {}
        self._asked: dict[str, tuple[int, float]] = {}

    def restart(self) -> None:
        """Forget everything (the flight controller rebooted: its parameters may differ)."""
        self.params.clear()
        self._asked.clear()

    def done(self, now_s: float) -> bool:
        """Every wanted name is answered, or has used up its attempts and its last request
        has had ``request_interval_s`` to be answered by local time ``now_s`` [s]."""
        attempts, wait_s = self.config.attempts, self.config.request_interval_s
        for name in wanted_names(self.autopilot, self.params):
            count, last_s = self._asked.get(name, (0, math.inf))
            if name not in self.params and (count < attempts or now_s - last_s < wait_s):
                return False
        return True

    def requests(self, now_s: float) -> list[MAVLinkMessage]:
        """PARAM_REQUEST_READ for every wanted name due at local time ``now_s`` [s]."""
        out = []
        for name in wanted_names(self.autopilot, self.params):
            if name in self.params:
                continue
            count, last_s = self._asked.get(name, (0, -math.inf))
            if count >= self.config.attempts or now_s - last_s < self.config.request_interval_s:
                continue
            self._asked[name] = (count + 1, now_s)
            out.append(
                dialect.MAVLink_param_request_read_message(
                    self.target[0], self.target[1], name.encode("ascii"), -1
                )
            )
        return out

    def on_param_value(self, msg: MAVLinkMessage) -> None:
        """Keep a PARAM_VALUE's value (a non-finite one is kept: the profile check names it)."""
        name = param_name(msg.param_id)
        bytewise = self.autopilot == "px4"
        self.params[name] = param_value(float(msg.param_value), msg.param_type, bytewise)


def require_mass(vehicle: str, config: AutopilotVehicleConfig) -> None:
    """``vehicle: from_autopilot`` needs ``autopilot_vehicle.mass_kg``."""
    if vehicle == FROM_AUTOPILOT and config.mass_kg is None:
        raise ConfigError(
            "",
            "autopilot_vehicle.mass_kg",
            None,
            "is required with vehicle: from_autopilot (the take-off mass [kg])",
        )

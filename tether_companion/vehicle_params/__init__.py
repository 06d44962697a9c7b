"""The vehicle profile from the flight controller's own parameters (ArduPilot or PX4).

:func:`tether_companion.vehicle_params.profile.profile_from_parameters` is pure (a mapping of
parameter names to values in, a :class:`VehicleProfile` out); :mod:`.sources` reads parameter
sets from logs.
"""

"""The simulator dressed as an ArduPilot-like flight controller speaking MAVLink."""

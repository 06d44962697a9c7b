"""ArduPilot SITL in the loop: start the real ArduCopter flight code on loopback, fly it as a
ground station would, and run ``tether-companion run`` against it (docs/ardupilot.md)."""

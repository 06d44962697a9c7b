"""tether-companion: localise a tethered drone from its tether's pull, over MAVLink.

Frames: NED world frame with its origin at the tether anchor; FRD body frame.
Units: SI inside the package (m, s, N, kg, rad); conversions happen only at the edges
(MAVLink decode/encode, config files, log loaders).
"""

__version__ = "0.1.0"

"""MAVLink edges: transports (UDP, TCP, serial, logs), decoding to SI samples, encoding."""

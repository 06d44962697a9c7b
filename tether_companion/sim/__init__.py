"""The offline simulator: sensors, controller, trajectories and scenarios."""

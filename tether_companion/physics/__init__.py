"""What is true of any tethered quadcopter: rigid body, motors, thrust curves, cable models.

Pure and synchronous: functions of state and parameters, no I/O and no hidden randomness.
"""

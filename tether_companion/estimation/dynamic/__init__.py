"""The dynamic tether filter of issue 10: position and velocity from the anchor, tension,
thrust scale, accelerometer bias and wind in one EKF whose model is derived symbolically
(``derivation/``) and generated as scalar Python (``generated.py``)."""

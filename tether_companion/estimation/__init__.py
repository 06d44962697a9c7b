"""Estimators: a generic continuous-discrete EKF and the tether models that plug into it."""

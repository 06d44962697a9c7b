"""Symbolic derivation of the dynamic tether filter's models (sympy; not imported at run time)."""

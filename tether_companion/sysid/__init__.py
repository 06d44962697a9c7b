"""Thrust-model identification from flight logs (Al-Radaideh & Sun 2021, section 5)."""

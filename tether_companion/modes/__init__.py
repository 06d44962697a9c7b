"""Tension-driven flight modes: tension-following and landing by the tether (Martins 2019)."""

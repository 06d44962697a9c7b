"""Write a vehicle profile as the YAML file ``load_vehicle`` reads back."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import yaml

from tether_companion.physics.vehicle import VehicleProfile


def profile_mapping(profile: VehicleProfile) -> dict[str, Any]:
    """Plain data of ``profile`` (tuples as lists; ``motors`` left out when a frame names them)."""

    def plain(value: Any) -> Any:
        if isinstance(value, (tuple, list)):
            return [plain(v) for v in value]
        if isinstance(value, dict):
            return {k: plain(v) for k, v in value.items()}
        return value

    data = plain(dataclasses.asdict(profile))
    if profile.frame != "custom":
        del data["motors"]
    return data


def save_profile(path: Path, profile: VehicleProfile, header: str) -> None:
    """Write ``profile`` to ``path`` with ``header`` as comment lines (OSError on failure)."""
    comments = "".join(f"# {line}\n" for line in header.splitlines())
    text = yaml.safe_dump(profile_mapping(profile), sort_keys=False, default_flow_style=None)
    path.write_text(comments + text, encoding="utf-8")

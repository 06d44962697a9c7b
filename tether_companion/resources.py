"""Locate the files that ship beside the package: configs/ and sitl/.

The project is installed editable (``pip install -e .``), so these folders sit next to the
``tether_companion`` package in the source tree.
"""

from __future__ import annotations

from pathlib import Path

PROJECT_ROOT: Path = Path(__file__).resolve().parent.parent
CONFIGS_DIR: Path = PROJECT_ROOT / "configs"
VEHICLES_DIR: Path = CONFIGS_DIR / "vehicles"
SCENARIOS_DIR: Path = PROJECT_ROOT / "sitl" / "scenarios"


def builtin_path(directory: Path, name: str) -> Path:
    """Return ``directory/name`` (``.yaml`` added when missing), failing clearly if absent.

    Raises
    ------
    FileNotFoundError
        When the file does not exist, naming the path looked for.
    """
    filename = name if name.endswith((".yaml", ".yml")) else f"{name}.yaml"
    path = directory / filename
    if not path.is_file():
        available = sorted(p.stem for p in directory.glob("*.yaml")) if directory.is_dir() else []
        raise FileNotFoundError(
            f"{path}: no such built-in file (available: {', '.join(available) or 'none'}); "
            "install the project editable (pip install -e .) so configs/ and sitl/ are found"
        )
    return path

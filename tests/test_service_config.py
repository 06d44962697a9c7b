"""Service configuration: the shipped files load; bad values stop `run` with exit code 2 and
a message naming the key, the value and what is allowed; the docs table is up to date."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tether_companion.cli import main
from tether_companion.config import ConfigError
from tether_companion.resources import CONFIGS_DIR, PROJECT_ROOT
from tether_companion.service.config import config_reference, load_service_config, load_vehicle_for


def test_shipped_config_and_the_built_in_defaults_run_the_dynamic_filter() -> None:
    config = load_service_config(CONFIGS_DIR / "companion.yaml")
    assert config.link.connect.startswith("serial:") and config.publish.rate_hz == 30.0
    assert config.estimator.kind == "dynamic"
    assert load_vehicle_for(config).n_motors == 4
    assert load_service_config(None).estimator.kind == "dynamic"
    # a partial estimator section keeps the service's default kind, not the paper's
    partial = load_service_config(None, {"estimator": {"min_cable_length_m": 0.5}})
    assert partial.estimator.kind == "dynamic"


def test_the_paper_filter_is_one_line_away_with_the_shipped_tuned_noise(tmp_path) -> None:
    """companion.yaml keeps the paper filters' tuned process noise (configs/estimator-tuned.yaml):
    switching to the paper's 4-state EKF is the one line ``kind: four_state``."""
    shipped = (CONFIGS_DIR / "companion.yaml").read_text(encoding="utf-8")
    assert shipped.count("kind: dynamic") == 1
    path = tmp_path / "companion.yaml"
    path.write_text(shipped.replace("kind: dynamic", "kind: four_state"), encoding="utf-8")
    config = load_service_config(path)
    assert config.estimator.kind == "four_state"
    assert config.estimator.process_noise.position_m2 == (5.0e-3, 5.0e-3, 2.5e-4)
    assert config.estimator.process_noise.tension_n2 == 1.0e-3


@pytest.mark.parametrize(
    ("yaml_text", "fragment"),
    [
        (
            "publish:\n  rate_hz: 0\n",
            r"publish.rate_hz = 0(\.0)?: must be a number >= 1.0 and <= 200.0",
        ),
        (
            "publish:\n  on_unhealthy: panic\n",
            "publish.on_unhealthy = 'panic': must be one of 'stop', 'inflate'",
        ),
        (
            "link:\n  fc_system_id: 300\n",
            r"link.fc_system_id = 300(\.0)?: must be an? integer >= 1 and <= 255",
        ),
        ("link:\n  connect: 'udp:nohost'\n", "link.connect = 'udp:nohost': missing host or port"),
        (
            "link:\n  bogus: 1\n",
            "link.bogus = 1: unknown key; allowed keys: autopilot, component_id",
        ),
        (
            "estimator:\n  kind: three_state\n",
            "tension.source = 'estimate': must be 'config' or 'message'",
        ),
        (
            "recording:\n  max_file_mb: 100\n  max_total_mb: 150\n",
            r"recording.max_total_mb = 150(\.0)?: must be >= 2 \* max_file_mb",
        ),
        ("vehicle: no-such-drone\n", "no such built-in file"),
        (
            "position:\n  source: gps\n",
            "position.source = 'gps': must be one of 'ekf', 'catenary'",
        ),
        (
            "catenary:\n  case: straight\n",
            "catenary.case = 'straight': must be one of 'lowest_point_at_anchor', 'known_length'",
        ),
        (
            "publish:\n  filtered_rate_hz: 100\n",
            r"publish.filtered_rate_hz = 100(\.0)?: must be a number >= 0.0 and <= 50.0",
        ),
        ("streams: [1, 2]\n", r"streams = \[1, 2\]: must be a mapping"),
    ],
)
def test_bad_config_exits_2_naming_key_value_allowed(
    tmp_path: Path, capsys, yaml_text: str, fragment: str
) -> None:
    path = tmp_path / "companion.yaml"
    path.write_text(yaml_text)
    code = main(["run", "--config", str(path), "--no-record"])
    err = capsys.readouterr().err
    assert code == 2
    assert str(path) in err or "no-such-drone" in err
    assert re.search(fragment, err), err
    assert "Traceback" not in err


def test_cli_overrides_are_validated_too(capsys) -> None:
    assert main(["run", "--connect", "serial:/dev/ttyAMA0:12345", "--no-record"]) == 2
    assert (
        "link.connect = 'serial:/dev/ttyAMA0:12345': baud rate 12345 is not a standard rate"
        in capsys.readouterr().err
    )


def test_unwritable_recording_directory_is_a_config_error(tmp_path: Path, capsys) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    code = main(["run", "--connect", "udp:127.0.0.1:9", "--record-dir", str(blocker / "rec")])
    assert code == 2
    assert "recording.directory" in capsys.readouterr().err


def test_three_state_with_known_tension_is_accepted() -> None:
    config = load_service_config(
        None,
        {
            "estimator": {"kind": "three_state"},
            "tension": {"source": "config", "known_tension_n": 6.0},
        },
    )
    assert config.estimator.kind == "three_state" and config.tension.known_tension_n == 6.0
    with pytest.raises(ConfigError, match="tension.message_name"):
        load_service_config(None, {"tension": {"message_name": ""}})


def test_docs_config_reference_is_generated_from_the_code() -> None:
    """The service's own rows must match the code (the estimator's rows belong to its owners'
    docstrings and may move ahead of this file; regenerate with the command in the doc)."""
    doc = (PROJECT_ROOT / "docs" / "config-reference.md").read_text(encoding="utf-8")
    rows = [r for r in config_reference().splitlines() if not r.startswith("| `estimator.")]
    missing = [r for r in rows if r not in doc]
    hint = "regenerate: python -m tether_companion.service.config\n"
    assert not missing, hint + "\n".join(missing)

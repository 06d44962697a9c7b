"""The EKFs on the simulator, and the ``simulate`` command end to end (short runs)."""

from __future__ import annotations

import csv
import dataclasses
import importlib.util

import numpy as np
import pytest
import yaml

from tether_companion.cli import main
from tether_companion.estimation.config import EstimatorConfig
from tether_companion.estimation.metrics import rmse
from tether_companion.estimation.report import CSV_COLUMNS
from tether_companion.estimation.runner import run_scenario
from tether_companion.resources import SCENARIOS_DIR
from tether_companion.sim.scenario import load_scenario


def _short_scenario(tmp_path, duration_s: float, **changes) -> str:
    data = yaml.safe_load((SCENARIOS_DIR / "paper-circle.yaml").read_text())
    data["duration_s"] = duration_s
    data.update(changes)
    path = tmp_path / "short.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def test_four_state_converges_to_truth_on_simulated_flight() -> None:
    base = load_scenario("paper-circle")
    scenario = dataclasses.replace(base, duration_s=12.0, seed=7)
    result = run_scenario(scenario, EstimatorConfig())
    settled = rmse(result, start_s=6.0)
    for axis in ("north_m", "east_m", "down_m"):
        assert settled["4S"][axis] < 0.4, settled
        assert settled["3S"][axis] < 0.4, settled
    assert settled["4S"]["tension_n"] < 0.4
    # started 2.7 m away (paper x0): the error must have shrunk
    first = np.linalg.norm(result.position_4s_ned_m[0] - result.truth_position_ned_m[0])
    last = np.linalg.norm(result.position_4s_ned_m[-1] - result.truth_position_ned_m[-1])
    assert first > 1.0 and last < 0.5
    assert result.health_4s.resets == 0 and result.health_4s.nonfinite_rejected == 0
    assert len(result.time_s) == 12 * 200


def test_simulate_writes_csv_and_prints_rmse(tmp_path, capsys) -> None:
    scenario = _short_scenario(tmp_path, 2.0)
    out = tmp_path / "run.csv"
    assert main(["simulate", scenario, "--seed", "3", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "RMSE" in printed and "north" in printed and "tension" in printed
    with out.open() as handle:
        rows = list(csv.reader(handle))
    assert tuple(rows[0]) == CSV_COLUMNS
    assert len(rows) == 1 + 400
    values = np.array(rows[1:], dtype=float)
    assert np.isfinite(values).all()
    assert values[-1, 0] == pytest.approx(2.0)


@pytest.mark.skipif(
    importlib.util.find_spec("matplotlib") is None, reason="matplotlib not installed"
)
def test_simulate_writes_plots(tmp_path, capsys) -> None:
    scenario = _short_scenario(tmp_path, 1.0)
    assert main(["simulate", scenario, "--plots", str(tmp_path / "plots")]) == 0
    names = sorted(p.name for p in (tmp_path / "plots").glob("*.png"))
    assert names == [
        "fig08_trajectory.png",
        "fig09_position.png",
        "fig10_errors.png",
        "fig11_tension.png",
    ]


def test_bad_scenario_file_exits_2_with_clear_message(tmp_path, capsys) -> None:
    scenario = _short_scenario(tmp_path, 1.0, bogus_key=3)
    assert main(["simulate", scenario]) == 2
    err = capsys.readouterr().err
    assert "bogus_key" in err and "unknown key" in err and "Traceback" not in err
    negative = _short_scenario(tmp_path, -1.0)
    assert main(["simulate", negative]) == 2
    assert "duration_s" in capsys.readouterr().err
    assert main(["simulate", str(tmp_path / "missing.yaml")]) == 2
    assert "file not found" in capsys.readouterr().err


def test_bad_estimator_config_and_seed_exit_2(tmp_path, capsys) -> None:
    scenario = _short_scenario(tmp_path, 1.0)
    config = tmp_path / "est.yaml"
    config.write_text("altimeter_noise_variance_m2: -1\n")
    assert main(["simulate", scenario, "--config", str(config)]) == 2
    assert "altimeter_noise_variance_m2" in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:
        main(["simulate", scenario, "--seed", "-4"])
    assert info.value.code == 2
    assert "must be >= 0" in capsys.readouterr().err


def test_simulate_says_so_when_matplotlib_is_missing(tmp_path, capsys, monkeypatch) -> None:
    from tether_companion.commands import simulate

    def no_matplotlib(*args, **kwargs):
        raise ImportError("No module named 'matplotlib'")

    monkeypatch.setattr(simulate, "write_plots", no_matplotlib)
    scenario = _short_scenario(tmp_path, 0.5)
    assert main(["simulate", scenario, "--plots", str(tmp_path / "plots")]) == 0
    assert "matplotlib is not installed" in capsys.readouterr().out

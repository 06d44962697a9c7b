"""Battery-compensated identification: the logged voltage scales the motor commands before
fitting exactly as the estimator scales them when it runs the written model."""

from __future__ import annotations

import contextlib
import dataclasses

import numpy as np
import pytest

from tether_companion.bench.sysid import pack_range, true_thrust_input
from tether_companion.cli import main
from tether_companion.config import from_mapping
from tether_companion.mavlink.framing import dialect
from tether_companion.physics.battery import BatteryCompensation
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.service.config import load_service_config
from tether_companion.service.session import EstimationSession
from tether_companion.sim.scenario import load_scenario
from tether_companion.sim.simulator import Simulator
from tether_companion.sysid.battery import compensate_logs, compensated_pwm_us
from tether_companion.sysid.flight import (
    FlightPlan,
    fly,
    identification_scenario,
    record_identification_flight,
)
from tether_companion.sysid.identify import identify
from tether_companion.sysid.logs import load_flight_log
from tether_companion.sysid.processing import prepare
from tether_companion.sysid.recorders import open_recorder
from tether_companion.sysid.selection import select
from tether_companion.sysid.thrust_model import (
    LinearModelFile,
    LinearThrust,
    model_file_mapping,
    save_thrust_model,
    thrust_input_from_mapping,
)

SAG_PLAN = FlightPlan(cycle_amplitudes=(1.0, 1.3))
"""Two excitation cycles: a 48 s flight."""
SAG_V_PER_CELL_PER_MIN = 0.4
"""A fast sag (8 % of the voltage over the flight) so the test flight can be short."""


def sagging_scenario():
    base = load_scenario("hover")
    pack = dataclasses.replace(
        base.propulsion.battery, sag_v_per_cell_per_min=SAG_V_PER_CELL_PER_MIN
    )
    return dataclasses.replace(base, propulsion=dataclasses.replace(base.propulsion, battery=pack))


@pytest.fixture(scope="module")
def sagging_flight(tmp_path_factory):
    path = tmp_path_factory.mktemp("sag") / "sag.tlog"
    scenario = sagging_scenario()
    simulator = record_identification_flight(path, SAG_PLAN, scenario, seed=5)
    return path, simulator.vehicle, scenario


def _identify(log, vehicle, battery, structures):
    curve = vehicle.thrust_curve
    pwm_range = (curve.pwm_min_us, curve.pwm_max_us)
    logs, compensated, note = compensate_logs([log], battery, pwm_range)
    data = prepare(logs[0], vehicle.mass_kg, pwm_range)
    results = identify([data.estimation], [data.validation], pwm_range, structures)
    _, scores = select(results, [data.validation], pwm_range)
    return {r.structure: r for r in results}, scores, compensated, note


def _steady_error_n(result, battery, log, truth):
    """RMS difference [N] between the written model, run as the estimator runs it (fed each
    PWM sample and the voltage; 2 s apart, so a linear model restarts in steady state), and
    the true map, over the airborne samples of the last 40 % of the flight (lowest voltage)."""
    thrust_input = thrust_input_from_mapping(
        model_file_mapping(result.model.to_mapping(), {}, battery)
    )
    voltage, pwm = log.battery_voltage_v, log.pwm_us
    landing_s = SAG_PLAN.setpoints()[-1][0]
    late = (pwm.time_s > 0.6 * landing_s) & (pwm.time_s < landing_s)
    error = []
    for k, (t, p) in enumerate(zip(pwm.time_s[late][::20], pwm.values[late][::20], strict=True)):
        v = float(np.interp(t, voltage.time_s, voltage.values[:, 0]))
        thrust_input.set_battery_voltage_v(v)
        truth.set_battery_voltage_v(v)
        error.append(thrust_input.total_thrust_n(p, 2.0 * k) - truth.total_thrust_n(p, 2.0 * k))
    return float(np.sqrt(np.mean(np.square(error))))


def _compare(sagging_flight, structure, structures, bound):
    """Compensated vs uncompensated identification of ``structure``: its steady validation
    RMSE (against the measured thrust) and its steady error against the true map must both
    fall below ``bound`` times the uncompensated one's."""
    path, vehicle, scenario = sagging_flight
    log = load_flight_log(path)
    assert log.battery_voltage_v is not None
    battery = pack_range(scenario)
    raw, raw_scores, raw_compensated, _ = _identify(log, vehicle, BatteryCompensation(), structures)
    comp, comp_scores, compensated, note = _identify(log, vehicle, battery, structures)
    assert compensated and not raw_compensated
    assert "commands scaled" in note
    steady = (comp_scores[structure].steady_rmse_n, raw_scores[structure].steady_rmse_n)
    assert steady[0] < bound * steady[1], steady
    truth = true_thrust_input(vehicle, scenario.propulsion)
    errors = (
        _steady_error_n(comp[structure], battery, log, truth),
        _steady_error_n(raw[structure], None, log, truth),
    )
    assert errors[0] < bound * errors[1], errors


def test_compensated_static_map_holds_on_a_sagging_battery(sagging_flight):
    """The validation part (last 40 %) flies on the lowest voltage: the uncompensated map,
    fitted mostly on a fuller pack, is off there (measured 0.82 N steady validation RMSE,
    0.86 N from the true map); the compensated one much less (0.20 N, 0.32 N: the rest is the
    static fit bending with the transients it cannot model)."""
    _compare(sagging_flight, "static", ("static",), 0.5)


def test_compensated_dynamic_model_holds_on_a_sagging_battery(sagging_flight):
    """The same with the process model (measured 0.043 vs 0.91 N steady validation RMSE,
    0.016 vs 0.94 N from the true map)."""
    _compare(sagging_flight, "process", ("static", "process"), 0.1)


def test_linear_model_applies_the_identification_scaling():
    """A linear file with a battery range fed a voltage gives what the same model without it
    gives on the compensated pulse widths (one formula for both sides)."""
    battery = BatteryCompensation(voltage_max_v=16.8, voltage_min_v=13.2)
    common = {
        "input_operating_point": (0.5,) * 8,
        "thrust_operating_point_n": 10.0,
        "a": ((0.8,),),
        "b": ((0.1,) * 8,),
        "c": ((1.0,),),
        "d": ((0.5,) * 8,),
        "input_map": {"kind": "quadratic", "pwm_min_us": 1000.0, "pwm_max_us": 2000.0},
    }
    battery_keys = {"voltage_max_v": 16.8, "voltage_min_v": 13.2}
    with_battery = LinearThrust(from_mapping(LinearModelFile, {**common, "battery": battery_keys}))
    without = LinearThrust(from_mapping(LinearModelFile, common))
    with_battery.set_battery_voltage_v(15.5)
    without.set_battery_voltage_v(15.5)  # identified uncompensated: ignored
    pwm = np.array([1500.0, 1620.0, 1580.0, 1700.0])
    got = with_battery.total_thrust_n(pwm, 0.0)
    scaled = compensated_pwm_us(pwm, (1000.0, 2000.0), battery.ratio(15.5))
    assert got == pytest.approx(without.total_thrust_n(scaled, 0.0), abs=1e-9)
    assert abs(got - without.total_thrust_n(pwm, 0.0)) > 0.05


@pytest.mark.parametrize("suffix", [".tlog", ".bin", ".csv"])
def test_recorded_voltage_is_read_back(tmp_path, suffix):
    """The identification recorders write the battery voltage and the loaders read it on the
    flight controller's time (4 s of flight)."""
    scenario = identification_scenario(SAG_PLAN, sagging_scenario())
    simulator = Simulator(scenario, rng=np.random.default_rng(1))
    path = tmp_path / f"flight{suffix}"
    sensors = scenario.sensors
    truth = []
    with contextlib.closing(open_recorder(path, (sensors.range_min_m, sensors.range_max_m))) as out:
        for tick in fly(SAG_PLAN, simulator):
            out.write(*tick)
            truth.append((tick[0].time_s, tick[-1]))
            if tick[0].time_s >= 4.0:
                break
    voltage = load_flight_log(path).battery_voltage_v
    assert voltage is not None and len(voltage) >= 8
    times, volts = np.array(truth).T
    expected = np.interp(voltage.time_s, times, volts)
    assert np.max(np.abs(voltage.values[:, 0] - expected)) < 2e-3  # mV resolution
    assert volts[0] - volts[-1] > 0.03  # the sag is seen


def _ulog(path, battery):
    from sysid_synthetic import log_signals
    from test_sysid_logs import write_ulog

    write_ulog(path, log_signals(), battery)
    return path


def test_ulog_battery_status_voltage_is_read(tmp_path):
    """PX4 .ulg: battery_status voltage_v on PX4's time; disconnected samples are unknown."""
    rows = [(1.0 + 0.5 * k, 16.8 - 0.01 * k, True) for k in range(10)] + [(6.2, 0.0, False)]
    voltage = load_flight_log(_ulog(tmp_path / "batt.ulg", rows)).battery_voltage_v
    assert voltage is not None
    np.testing.assert_allclose(voltage.time_s, [r[0] for r in rows[:10]], atol=1e-6)
    np.testing.assert_allclose(voltage.values[:, 0], [r[1] for r in rows[:10]], atol=1e-6)
    assert load_flight_log(_ulog(tmp_path / "none.ulg", [])).battery_voltage_v is None


def test_sysid_compensates_a_ulog_flight(tmp_path, capsys):
    """sysid on a .ulg with battery_status scales the commands like on .tlog/.bin/.csv."""
    rows = [(0.5 + 0.5 * k, 16.8 - 0.005 * k, True) for k in range(80)]  # to 40 s
    path = _ulog(tmp_path / "flight.ulg", rows)
    range_args = ["--battery-voltage-max-v", "16.8", "--battery-voltage-min-v", "13.2"]
    out = tmp_path / "model.yaml"
    assert main(["sysid", str(path), "--structure", "static", *range_args, "--out", str(out)]) == 0
    printed = " ".join(capsys.readouterr().out.split())
    assert "battery: logged 16.41-16.80 V; commands scaled by the voltage ratio" in printed
    assert "voltage_max_v: 16.8" in out.read_text(encoding="utf-8")


@pytest.mark.parametrize("bad", [float("nan"), 0.0, -12.1])
def test_ulog_voltage_that_is_not_a_positive_number_exits_2(tmp_path, capsys, bad):
    rows = [(1.0, 16.8, True), (1.5, bad, True), (2.0, 16.7, True)]
    assert main(["sysid", str(_ulog(tmp_path / "bad.ulg", rows))]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert "battery_status at 1.500 s: voltage_v = " in err and "not a positive voltage" in err


def _csv(path, voltages):
    header = "time_s,pwm1_us,pwm2_us,pwm3_us,pwm4_us,acc_x_mps2,acc_y_mps2,acc_z_mps2,"
    rows = [header + "roll_rad,pitch_rad,yaw_rad,battery_voltage_v"]
    for k, v in enumerate(voltages):
        rows.append(f"{0.01 * k},1500,1500,1500,1500,0,0,-9.8,0,0,0,{v}")
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


@pytest.mark.parametrize("bad", ["nan", "0", "-12.1"])
def test_csv_voltage_that_is_not_a_positive_number_exits_2(tmp_path, capsys, bad):
    path = _csv(tmp_path / "bad.csv", ["16.8", bad, "16.7"])
    assert main(["sysid", str(path)]) == 2
    err = capsys.readouterr().err
    assert "line 3: column battery_voltage_v" in err and "positive voltage" in err


def test_empty_voltage_cells_are_missing_samples(tmp_path):
    log = load_flight_log(_csv(tmp_path / "ok.csv", ["16.8", "", "16.7"]))
    assert log.battery_voltage_v is not None and len(log.battery_voltage_v) == 2


def test_voltage_range_with_min_not_below_max_exits_2(sagging_flight, capsys):
    path, _, _ = sagging_flight
    args = ["sysid", str(path), "--structure", "static", "--battery-voltage-max-v", "14"]
    assert main([*args, "--battery-voltage-min-v", "14"]) == 2
    err = capsys.readouterr().err
    assert "battery.voltage_min_v = 14.0: must be < voltage_max_v (14.0)" in err


def test_without_voltage_or_range_sysid_says_so_in_one_line(sagging_flight, tmp_path, capsys):
    path, _, _ = sagging_flight
    out = tmp_path / "m.yaml"
    assert main(["sysid", str(path), "--structure", "static", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "but no voltage range is known" in printed
    assert "battery:" not in out.read_text(encoding="utf-8")
    assert (
        main(
            [
                "sysid",
                str(path),
                "--structure",
                "static",
                "--out",
                str(out),
                "--battery-voltage-max-v",
                "16.8",
                "--battery-voltage-min-v",
                "13.2",
            ]
        )
        == 0
    )
    assert "commands scaled" in capsys.readouterr().out
    assert "voltage_max_v: 16.8" in out.read_text(encoding="utf-8")


def test_service_passes_the_voltage_to_a_compensated_model_file(tmp_path):
    """The service's estimator runs the written file and feeds it the FC's SYS_STATUS."""
    curve = {"pwm_min_us": 1000.0, "pwm_max_us": 2000.0, "coefficients_n": [0.0, 0.5, 7.5]}
    model = {"kind": "static", "n_motors": 4, "thrust_curve": curve}
    battery = BatteryCompensation(voltage_max_v=16.8, voltage_min_v=13.2)
    path = tmp_path / "thrust.yaml"
    save_thrust_model(path, model_file_mapping(model, {}, battery), "test")
    overrides = {"recording": {"enabled": False}, "estimator": {"thrust_model": str(path)}}
    session = EstimationSession(
        load_service_config(None, overrides), load_vehicle("realistic-quad")
    )
    msg = dialect.MAVLink_sys_status_message(0, 0, 0, 500, 15960, -1, -1, 0, 0, 0, 0, 0, 0)
    msg.pack(dialect.MAVLink(None, srcSystem=1, srcComponent=1))
    session.on_message(msg)
    assert session.aligner.thrust_input.voltage_ratio == pytest.approx(0.95)

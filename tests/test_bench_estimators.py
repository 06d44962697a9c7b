"""``bench estimators``: NEES and band against closed forms, a tiny scorecard on a local Dask
cluster, the same numbers through a scheduler started here, bad input."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tether_companion.bench.estimators import cluster
from tether_companion.bench.estimators.flight import FlightRecord, KindTrace
from tether_companion.bench.estimators.registry import kinds
from tether_companion.bench.estimators.scores import (
    TAUT_TENSION_N,
    converge_time_s,
    nees,
    nees_band,
    pool,
    published_after_taut_s,
    score_kind,
    share_in_band,
)
from tether_companion.cli import main

TINY = [
    "bench",
    "estimators",
    "--seeds",
    "2",
    "--duration-s",
    "4",
    "--settle-s",
    "1",
    "--scenario",
    "hover",
    "--json",
]


def _random_spd(rng: np.random.Generator, n: int) -> np.ndarray:
    a = rng.standard_normal((n, 3, 3))
    return a @ np.transpose(a, (0, 2, 1)) + 0.1 * np.eye(3)


def test_nees_is_the_quadratic_form_and_nan_where_undefined():
    rng = np.random.default_rng(3)
    cov = _random_spd(rng, 5)
    err = rng.standard_normal((5, 3))
    expected = [float(e @ np.linalg.inv(p) @ e) for e, p in zip(err, cov, strict=True)]
    err[4] = np.nan
    cov[3] = np.nan
    got = nees(err, cov)
    np.testing.assert_allclose(got[:3], expected[:3], rtol=1e-10)
    assert math.isnan(got[3]) and math.isnan(got[4])
    singular = np.zeros((1, 3, 3))
    assert math.isnan(nees(np.ones((1, 3)), singular)[0])


def test_nees_band_is_the_chi_square_quantiles():
    """chi2(3) 2.5 % / 97.5 %: 0.2158 / 9.348; 10 runs: chi2(30) / 10 = 1.679 / 4.698."""
    low, high = nees_band(1)
    assert (float(low), float(high)) == pytest.approx((0.2158, 9.3484), abs=1e-4)
    low, high = nees_band(10)
    assert (float(low), float(high)) == pytest.approx((1.6791, 4.6979), abs=1e-4)


def test_consistent_errors_lie_in_the_band_95_percent_of_the_time():
    """Errors drawn from the stated covariance: the 10-run average is in its band ~95 % of
    ticks (binomial sd over 4000 ticks: 0.35 %); errors twice as large almost never."""
    rng = np.random.default_rng(7)
    runs, ticks = 10, 4000
    cov = _random_spd(rng, ticks)
    chol = np.linalg.cholesky(cov)
    values = np.empty((runs, ticks))
    for r in range(runs):
        err = np.einsum("tij,tj->ti", chol, rng.standard_normal((ticks, 3)))
        values[r] = nees(err, cov)
    assert share_in_band(values) == pytest.approx(0.95, abs=0.015)
    assert share_in_band(4.0 * values) < 0.02
    values[:5, :100] = np.nan  # fewer runs on some ticks: their band widens, share stays
    assert share_in_band(values) == pytest.approx(0.95, abs=0.015)
    assert math.isnan(share_in_band(np.full((2, 3), np.nan)))


def test_beyond_3_sigma_is_0_8_percent_for_consistent_errors_and_counts_published_apart():
    """Errors drawn from the stated (diagonal) covariance: some axis beyond 3 sigma on
    1 - 0.9973^3 = 0.81 % of ticks (binomial sd over 40000 ticks: 0.045 %); errors twice as
    large about 13.2 %. Of the published ticks only those count: publishing just the ticks
    beyond gives 100 %."""
    rng = np.random.default_rng(11)
    n = 40_000
    sigma = rng.uniform(0.05, 2.0, (n, 3))
    covariance = np.zeros((n, 3, 3))
    covariance[:, [0, 1, 2], [0, 1, 2]] = sigma**2
    error = sigma * rng.standard_normal((n, 3))
    zeros = np.zeros((n, 3))
    record = FlightRecord(
        time_s=np.arange(n) * 0.005,
        position_ned_m=zeros,
        velocity_ned_mps=zeros,
        euler_rad=zeros,
        tension_n=np.zeros(n),
        thrust_n=np.zeros(n),
        range_seen=np.zeros(n, dtype=bool),
        cable_force_ned_n=zeros,
        wind_ned_mps=zeros,
        specific_force_body_mps2=zeros,
        angle_seen=np.zeros(n, dtype=bool),
        winch_seen=np.zeros(n, dtype=bool),
        landed=np.zeros(n, dtype=bool),
        traces={},
    )

    def cell(scale: float, published: np.ndarray) -> dict:
        trace = KindTrace(
            position_ned_m=scale * error,
            position_covariance_m2=covariance,
            velocity_ned_mps=np.full((n, 3), np.nan),
            tension_n=np.full(n, np.nan),
            tension_variance_n2=np.full(n, np.nan),
            published=published,
        )
        return pool([score_kind(record, trace, zeros, 0.0, 0.5)], False, False)

    everywhere = cell(1.0, np.ones(n, dtype=bool))
    assert everywhere["beyond_3_sigma"] == pytest.approx(1.0 - 0.9973**3, abs=0.0015)
    assert everywhere["published_beyond_3_sigma"] == everywhere["beyond_3_sigma"]
    assert cell(2.0, np.ones(n, dtype=bool))["beyond_3_sigma"] == pytest.approx(
        1.0 - 0.8664**3, abs=0.01
    )
    only_beyond = np.any(np.abs(error) > 3.0 * sigma, axis=1)
    picked = cell(1.0, only_beyond)
    assert picked["published_beyond_3_sigma"] == 1.0
    assert math.isnan(cell(1.0, np.zeros(n, dtype=bool))["published_beyond_3_sigma"])


def test_converge_time():
    t = np.arange(6) * 1.0
    assert converge_time_s(t, np.array([2, 1, 0.4, 0.6, 0.1, 0.1]), 0.5) == 4.0
    assert converge_time_s(t, np.full(6, 0.1), 0.5) == 0.0
    assert converge_time_s(t, np.array([0.1, 0.1, 0.1, 0.1, 0.1, 0.9]), 0.5) == math.inf
    assert math.isnan(converge_time_s(t, np.full(6, np.nan), 0.5))


def test_builtin_kinds_are_registered():
    registry = kinds()
    assert {"ekf-4s", "ekf-3s", "catenary"} <= set(registry)


def _run_json(capsys, argv: list[str]) -> dict:
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


@pytest.fixture(scope="module")
def local_card():
    """The tiny scorecard on a local cluster of one process (computed once)."""
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main([*TINY, "--workers", "1"]) == 0
    return json.loads(out.getvalue())


def test_tiny_scorecard_on_a_local_cluster(local_card):
    card = local_card["scenarios"]["hover"]
    assert set(card) == set(kinds())
    assert local_card["seeds"] == [1, 2] and local_card["flights"] == 2
    for name, cell in card.items():
        assert cell["seeds"] == 2
        assert 0.0 <= cell["share_published"] <= 1.0
        assert cell["crlb_horizontal_m"] > 0.0 and cell["crlb_vertical_m"] > 0.0
        # hover at 4 N: every kind is close, or says it cannot be (the dynamic filter does not
        # take the thrust map as exact; in a steady hover its thrust scale trades against the
        # cable's vertical pull, and it withholds the position as weak_pull)
        assert cell["horizontal_rmse_m"] < 1.0 or cell["share_published"] < 0.5, name
        assert cell["nees_mean"] > 0.0
        # the pooled RMSE is a tick-weighted RMS of the per-seed ones, so it lies between them
        per_seed = cell["horizontal_rmse_per_seed_m"]
        assert len(per_seed) == 2
        assert min(per_seed) - 1e-12 <= cell["horizontal_rmse_m"] <= max(per_seed) + 1e-12
        has_velocity = kinds()[name].has_velocity
        assert (cell["velocity_rmse_mps"] is None) == (not has_velocity), name
    assert card["ekf-3s"]["tension_rmse_n"] is None
    assert card["ekf-4s"]["tension_rmse_n"] < 0.5
    # the own-model bound: the dynamic kinds have one (the winch's length adds information),
    # the paper filters none (null in JSON)
    assert card["ekf-4s"]["own_bound_horizontal_m"] is None
    imu_only, winch = card["dynamic"], card["dynamic-winch"]
    assert 0.0 < winch["own_bound_horizontal_m"] < imu_only["own_bound_horizontal_m"]
    angle = card["dynamic-angle"]["own_bound_horizontal_m"]
    assert 0.0 < angle < imu_only["own_bound_horizontal_m"]
    assert imu_only["horizontal_rmse_over_own_bound"] == pytest.approx(
        imu_only["horizontal_rmse_m"] / imu_only["own_bound_horizontal_m"]
    )


def test_unknown_estimator_and_empty_window_exit_2(capsys):
    assert main([*TINY, "--estimator", "nope"]) == 2
    err = capsys.readouterr().err
    assert "'nope' is not a registered kind" in err and err.count("\n") == 1
    assert main([*TINY, "--settle-s", "4"]) == 2
    assert "leaves nothing to score" in capsys.readouterr().err
    assert main([*TINY, "--scenario", "no-such-scenario"]) == 2
    with pytest.raises(SystemExit) as exit_info:
        main([*TINY, "--seeds", "0"])
    assert exit_info.value.code == 2


def test_without_distributed_exits_2_saying_what_to_install(capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import raises ImportError
    assert main(TINY) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pip install 'tether-companion[bench]'" in err


def test_unreachable_scheduler_exits_2(capsys, monkeypatch):
    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT_S", 1.0)
    assert main([*TINY, "--scheduler", "tcp://127.0.0.1:9"]) == 2
    err = capsys.readouterr().err
    assert "cannot reach the dask scheduler at 'tcp://127.0.0.1:9'" in err
    assert err.count("\n") == 1


def _scheduler_address(path: Path, process: subprocess.Popen, timeout_s: float = 60.0) -> str:
    """The address in the scheduler file ``path`` once ``process`` has written it whole (the
    file exists, empty, for a moment before its JSON is in it: read then, on a busy machine,
    it failed to parse)."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return json.loads(path.read_text())["address"]
        except (FileNotFoundError, json.JSONDecodeError, KeyError):
            pass
        if process.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"{process.args} did not start (exit {process.poll()})")
        time.sleep(0.1)


@pytest.mark.integration
def test_scheduler_gives_the_local_numbers(local_card, tmp_path, capsys):
    """A dask scheduler and one worker as real processes on 127.0.0.1; the same seeds give
    the same scorecard as the local cluster, to the last digit."""
    scheduler_file = tmp_path / "scheduler.json"
    common = ["--no-dashboard"]
    scheduler = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "distributed.cli.dask_scheduler",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            "--scheduler-file",
            str(scheduler_file),
            *common,
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    worker = None
    try:
        address = _scheduler_address(scheduler_file, scheduler)
        assert address.startswith("tcp://127.0.0.1:")
        worker = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "distributed.cli.dask_worker",
                address,
                "--nworkers",
                "1",
                "--nthreads",
                "1",
                "--host",
                "127.0.0.1",
                *common,
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        remote = _run_json(capsys, [*TINY, "--scheduler", address])
    finally:
        for process in (worker, scheduler):
            if process is not None:
                process.terminate()
                try:
                    process.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    process.kill()
    assert remote["scheduler"] == address and remote["workers"] == 1
    assert remote["scenarios"] == local_card["scenarios"]


def test_plot_writes_one_png_per_scenario(tmp_path):
    pytest.importorskip("matplotlib", reason="matplotlib is not installed (the plot extra)")
    import dataclasses

    from tether_companion.bench.estimators.report import write_plots
    from tether_companion.bench.estimators.tasks import FlightTask, score_flight
    from tether_companion.sim.scenario import load_scenario

    selected = [kinds()["ekf-4s"], kinds()["catenary"]]
    scenario = dataclasses.replace(load_scenario("hover"), duration_s=3.0, seed=1)
    score = score_flight(FlightTask("hover", scenario, ("ekf-4s", "catenary"), 1.0, 0.5))
    written = write_plots(tmp_path / "plots", [score], selected, ["hover"])
    assert written == [tmp_path / "plots" / "estimators-hover.png"]
    assert written[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_paper_filters_are_told_the_anchor_height_and_the_rangefinder_mounting():
    """The ground-station facts a user writes into ``estimator:`` reach the paper filters: on a
    hover with the winch on a 1.5 m stand and the rangefinder 0.3 m below the centre of mass
    (nothing else off), the 4-state EKF's height is right, not 1.5 - 0.3 m off."""
    import dataclasses

    from tether_companion.bench.estimators.flight import fly
    from tether_companion.bench.estimators.registry import FlightContext
    from tether_companion.estimation.config import load_estimator_config
    from tether_companion.physics.vehicle import load_vehicle
    from tether_companion.sim.ground import GroundConfig
    from tether_companion.sim.scenario import load_scenario

    base = load_scenario("hover")
    scenario = dataclasses.replace(
        base,
        duration_s=6.0,
        seed=1,
        ground=GroundConfig(anchor_height_m=1.5),
        sensors=dataclasses.replace(base.sensors, range_offset_frd_m=(0.0, 0.0, 0.3)),
    )
    context = FlightContext(scenario, load_vehicle(scenario.vehicle), 9.80665)
    config = context.estimator_config(load_estimator_config())
    assert config.ground_station.anchor_height_m == 1.5
    assert config.rangefinder.offset_frd_m == (0.0, 0.0, 0.3)
    record = fly(scenario, [kinds()["ekf-4s"]])
    late = record.time_s >= 3.0
    down_error = record.traces["ekf-4s"].position_ned_m[late, 2] - record.position_ned_m[late, 2]
    assert np.sqrt(np.mean(down_error**2)) < 0.2  # 1.2 m if the stand were taken for ground


def test_published_after_taut_counts_from_lift_off_with_the_cable_pulling() -> None:
    """The issue's "position published within 5 s of the cable becoming taut": from the first
    tick off the ground with the true tension above TAUT_TENSION_N to the first published tick
    at or after it; ticks published on the ground or before it do not count; never published
    after it is inf, never taut nan."""
    time_s = np.arange(10) * 0.5
    landed = np.array([True] * 4 + [False] * 6)
    tension = np.array([3.0] * 5 + [0.1] + [3.0] * 4)  # lift-off at 2.0 s, slack at 2.5 s
    published = np.zeros(10, dtype=bool)
    published[1] = True  # on the ground: does not count
    assert published_after_taut_s(time_s, landed, tension, published) == math.inf
    published[7] = True
    assert published_after_taut_s(time_s, landed, tension, published) == pytest.approx(1.5)
    slack = np.full(10, TAUT_TENSION_N)  # never above: never taut
    assert math.isnan(published_after_taut_s(time_s, landed, slack, published))

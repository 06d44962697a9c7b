"""The scorecard's outputs: pooled scores per scenario, rich tables, JSON, plots."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from tether_companion.bench.estimators.registry import EstimatorKind
from tether_companion.bench.estimators.scores import pool
from tether_companion.bench.estimators.tasks import FlightScore


def scorecard(
    scores: list[FlightScore], selected: list[EstimatorKind], scenario_names: list[str]
) -> dict[str, dict[str, dict]]:
    """scenario -> kind -> pooled scores (seeds pooled in seed order, whatever the finish
    order on the cluster)."""
    ordered = sorted(scores, key=lambda s: (scenario_names.index(s.scenario_name), s.seed))
    out: dict[str, dict[str, dict]] = {}
    for name in scenario_names:
        flights = [s for s in ordered if s.scenario_name == name]
        out[name] = {
            kind.name: pool(
                [f.kinds[kind.name] for f in flights], kind.has_tension, kind.has_velocity
            )
            for kind in selected
        }
    return out


def json_safe(value: Any) -> Any:
    """``value`` with non-finite floats as ``None`` (strict JSON has no NaN or Infinity)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value


def _f(value: float | None, digits: int = 3) -> str:
    if value is None:
        return "-"
    if math.isnan(value):
        return "n/a"
    if math.isinf(value):
        return "never"
    return f"{value:.{digits}f}"


def _pct(value: float, digits: int = 0) -> str:
    return "n/a" if math.isnan(value) else f"{100.0 * value:.{digits}f} %"


ROWS = (
    ("horizontal RMSE [m]", lambda c: _f(c["horizontal_rmse_m"])),
    ("vertical RMSE [m]", lambda c: _f(c["vertical_rmse_m"])),
    ("max 3-D error [m]", lambda c: _f(c["max_error_m"])),
    ("tension RMSE [N]", lambda c: _f(c["tension_rmse_n"])),
    ("velocity RMSE [m/s]", lambda c: _f(c["velocity_rmse_mps"])),
    ("NEES mean (3 dof: 3)", lambda c: _f(c["nees_mean"], 2)),
    ("NEES in 95 % band", lambda c: _pct(c["nees_in_band"])),
    ("time to converge [s]", lambda c: _converge(c)),
    ("share published", lambda c: _pct(c["share_published"])),
    ("published after taut, worst seed [s]", lambda c: _after_taut(c)),
    ("beyond 3 sigma (consistent: 0.8 %)", lambda c: _pct(c["beyond_3_sigma"], 1)),
    ("published beyond 3 sigma", lambda c: _pct(c["published_beyond_3_sigma"], 1)),
    ("CRLB horizontal [m]", lambda c: _f(c["crlb_horizontal_m"])),
    ("CRLB vertical [m]", lambda c: _f(c["crlb_vertical_m"])),
    ("RMSE / CRLB horizontal", lambda c: _f(c["horizontal_rmse_over_crlb"], 2)),
    ("RMSE / CRLB vertical", lambda c: _f(c["vertical_rmse_over_crlb"], 2)),
    ("own-model CRLB horizontal [m]", lambda c: _f(c["own_bound_horizontal_m"])),
    ("own-model CRLB vertical [m]", lambda c: _f(c["own_bound_vertical_m"])),
    ("RMSE / own CRLB horizontal", lambda c: _f(c["horizontal_rmse_over_own_bound"], 2)),
    ("RMSE / own CRLB vertical", lambda c: _f(c["vertical_rmse_over_own_bound"], 2)),
)
"""The table's rows: label and how a pooled cell is shown."""


def _after_taut(cell: dict) -> str:
    """The slowest seed's seconds from taut to the first published tick, with how many
    seeds never published after it ("-": the cable was never taut)."""
    times = [t for t in cell["published_after_taut_s_per_seed"] if not math.isnan(t)]
    if not times:
        return "-"
    never = sum(1 for t in times if math.isinf(t))
    finite = [t for t in times if math.isfinite(t)]
    text = _f(max(finite), 1) if finite else "never"
    return f"{text} ({never}/{len(times)} never)" if never and finite else text


def _converge(cell: dict) -> str:
    never = cell["never_converged"]
    text = _f(cell["converge_s_median"], 1)
    return f"{text} ({never}/{cell['seeds']} never)" if never else text


def scenario_table(
    name: str, cells: dict[str, dict], selected: list[EstimatorKind], caption: str
) -> Table:
    """One scenario's rich table: a row per score, a column per kind."""
    table = Table(title=escape(name), caption=escape(caption))
    table.add_column("score")
    for kind in selected:
        table.add_column(escape(kind.label), justify="right")
    for label, show in ROWS:
        table.add_row(escape(label), *(show(cells[kind.name]) for kind in selected))
    return table


def print_tables(
    console: Console,
    card: dict[str, dict[str, dict]],
    selected: list[EstimatorKind],
    seeds: int,
    settle_s: float,
    converged_m: float,
) -> None:
    """Every scenario's table and a legend."""
    caption = (
        f"{seeds} seed(s), scored from {settle_s:g} s; converge: error < {converged_m:g} m to "
        f"the end (median over seeds); CRLB: posterior bound for the paper's random-walk "
        f"model (estimation/crlb.py); own-model CRLB: the bound of the kind's own model and "
        f"measurements (the dynamic kinds: estimation/dynamic/crlb.py; n/a: none)"
    )
    for name, cells in card.items():
        console.print(scenario_table(name, cells, selected, caption))


def write_plots(
    directory: Path,
    scores: list[FlightScore],
    selected: list[EstimatorKind],
    scenario_names: list[str],
) -> list[Path]:
    """One PNG per scenario: horizontal and vertical error of each seed, the kind's 3-sigma
    and 3x the CRLB sigma over time. Needs matplotlib (the ``plot`` extra)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for name in scenario_names:
        flights = sorted((s for s in scores if s.scenario_name == name), key=lambda s: s.seed)
        figure, axes = plt.subplots(
            len(selected), 2, figsize=(12, 2.6 * len(selected)), sharex=True, squeeze=False
        )
        for row, kind in enumerate(selected):
            for col, axis_name in enumerate(("horizontal", "vertical")):
                ax = axes[row][col]
                for i, flight in enumerate(flights):
                    series = flight.kinds[kind.name].series
                    t = series["time_s"]
                    first = i == 0
                    ax.plot(
                        t,
                        series[f"{axis_name}_error_m"],
                        color="C0",
                        lw=0.7,
                        alpha=0.6,
                        label="|error|" if first else None,
                    )
                    ax.plot(
                        t,
                        series[f"{axis_name}_3sigma_m"],
                        color="C1",
                        lw=0.7,
                        alpha=0.6,
                        label="3 sigma (filter)" if first else None,
                    )
                    ax.plot(
                        t,
                        3.0 * series[f"crlb_{axis_name}_m"],
                        color="C2",
                        lw=0.7,
                        ls="--",
                        alpha=0.6,
                        label="3 sigma (CRLB)" if first else None,
                    )
                ax.set_title(f"{kind.label}: {axis_name}", fontsize=9)
                ax.set_ylabel("m")
                ax.set_yscale("log")
                if row == 0 and col == 0:
                    ax.legend(fontsize=7)
            axes[-1][0].set_xlabel("time [s]")
            axes[-1][1].set_xlabel("time [s]")
        figure.suptitle(f"{name}: error and 3 sigma, {len(flights)} seed(s)")
        figure.tight_layout()
        path = directory / f"estimators-{Path(name).stem}.png"
        figure.savefig(path, dpi=90)
        plt.close(figure)
        written.append(path)
    return written

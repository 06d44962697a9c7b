"""Outputs of an offline run: CSV time series, an RMSE table, and the paper's Figs 8-11 as PNG."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from rich.markup import escape
from rich.table import Table

from tether_companion.estimation.metrics import AXES
from tether_companion.estimation.runner import RunResult

CSV_COLUMNS: tuple[str, ...] = (
    "time_s",
    "true_n_m",
    "true_e_m",
    "true_d_m",
    "true_tension_n",
    "ekf4_n_m",
    "ekf4_e_m",
    "ekf4_d_m",
    "ekf4_tension_n",
    "ekf4_var_n_m2",
    "ekf4_var_e_m2",
    "ekf4_var_d_m2",
    "ekf4_var_tension_n2",
    "ekf3_n_m",
    "ekf3_e_m",
    "ekf3_d_m",
    "ekf3_var_n_m2",
    "ekf3_var_e_m2",
    "ekf3_var_d_m2",
)


def write_csv(result: RunResult, path: Path) -> None:
    """One row per IMU tick with the columns of :data:`CSV_COLUMNS` (SI units)."""
    data = np.column_stack(
        (
            result.time_s,
            result.truth_position_ned_m,
            result.truth_tension_n,
            result.position_4s_ned_m,
            result.tension_4s_n,
            result.variance_4s,
            result.position_3s_ned_m,
            result.variance_3s,
        )
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(CSV_COLUMNS)
        writer.writerows([f"{v:.6g}" for v in row] for row in data.tolist())


def rmse_table(table: dict[str, dict[str, float]], title: str) -> Table:
    """A rich table of RMSE per filter (rows N/E/D/tension, columns 3S and 4S)."""
    out = Table(title=title)
    out.add_column("RMSE")
    out.add_column("3S (known tension)", justify="right")
    out.add_column("4S", justify="right")
    for key, label in ((AXES[0], "north [m]"), (AXES[1], "east [m]"), (AXES[2], "down [m]")):
        out.add_row(escape(label), f"{table['3S'][key]:.3f}", f"{table['4S'][key]:.3f}")
    out.add_row(escape("tension [N]"), "-", f"{table['4S']['tension_n']:.3f}")
    return out


def write_plots(result: RunResult, directory: Path, label: str) -> list[Path]:
    """PNG figures like the paper's Figs 8 (trajectory), 9 (N/E/D), 10 (errors, 3 sigma of
    the 4-state filter) and 11 (tension). Needs matplotlib (raises ImportError without)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    directory.mkdir(parents=True, exist_ok=True)
    t = result.time_s
    truth, p3, p4 = result.truth_position_ned_m, result.position_3s_ned_m, result.position_4s_ned_m
    paths = []

    fig = plt.figure(figsize=(14, 4.5))
    ax3d = fig.add_subplot(1, 3, 1, projection="3d")
    for data, name, style, width in (
        (p3, "EKF3S", "b-", 0.6),
        (p4, "EKF4S", "r-", 0.6),
        (truth, "Truth", "k-", 1.5),
    ):
        ax3d.plot(data[:, 1], data[:, 0], -data[:, 2], style, lw=width, label=name)
    ax3d.set_xlabel("east [m]")
    ax3d.set_ylabel("north [m]")
    ax3d.set_zlabel("height [m]")
    ax3d.legend()
    for index, (xi, yi, xlabel, ylabel, title) in enumerate(
        (
            (1, 0, "east [m]", "north [m]", "top view"),
            (0, 2, "north [m]", "height [m]", "side view"),
        ),
        start=2,
    ):
        ax = fig.add_subplot(1, 3, index)
        for data, style, width in ((p3, "b-", 0.6), (p4, "r-", 0.6), (truth, "k-", 1.5)):
            y = -data[:, yi] if yi == 2 else data[:, yi]
            ax.plot(data[:, xi], y, style, lw=width)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        ax.grid(True)
    fig.suptitle(f"Trajectory, truth and estimates ({label})")
    paths.append(_save(fig, directory / "fig08_trajectory.png"))

    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    for i, (ax, name) in enumerate(zip(axes, ("north", "east", "down"), strict=True)):
        ax.plot(t, p3[:, i], "b-", lw=0.6, label="EKF3S")
        ax.plot(t, p4[:, i], "r-", lw=0.6, label="EKF4S")
        ax.plot(t, truth[:, i], "k-", lw=1.5, label="Truth")
        ax.set_ylabel(f"{name} [m]")
        ax.grid(True)
    axes[0].legend(loc="upper right")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"Position estimates ({label})")
    paths.append(_save(fig, directory / "fig09_position.png"))

    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    for i, (ax, name) in enumerate(zip(axes, ("north", "east", "down"), strict=True)):
        sigma3 = 3.0 * np.sqrt(result.variance_4s[:, i])
        ax.plot(t, p3[:, i] - truth[:, i], "b-", lw=0.7, label="3s")
        ax.plot(t, p4[:, i] - truth[:, i], "r-", lw=0.7, label="4s")
        ax.plot(t, sigma3, "g--", lw=0.8, label="3 sigma (4s)")
        ax.plot(t, -sigma3, "g--", lw=0.8)
        ax.set_ylabel(f"{name} error [m]")
        ax.grid(True)
    axes[0].legend(loc="upper right")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"Position errors ({label})")
    paths.append(_save(fig, directory / "fig10_errors.png"))

    fig, ax = plt.subplots(figsize=(10, 4))
    ax.plot(t, result.tension_4s_n, "r-", lw=0.6, label="EKF4S")
    ax.plot(t, result.truth_tension_n, "b-", lw=1.5, label="Truth")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("cable tension [N]")
    ax.grid(True)
    ax.legend()
    ax.set_title(f"Cable tension ({label})")
    paths.append(_save(fig, directory / "fig11_tension.png"))
    return paths


def _save(fig, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path

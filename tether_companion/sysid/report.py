"""Printing identification results: the paper's Table 1 as a rich table, and a plot."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from rich.markup import escape
from rich.table import Table

from tether_companion.errors import InputError
from tether_companion.sysid.identify import StructureResult
from tether_companion.sysid.processing import IdData
from tether_companion.sysid.selection import DC_TOLERANCE_PCT, SelectionScore

BEST_MARK = "*"
WRITTEN_MARK = "->"


def results_table(
    results: Sequence[StructureResult],
    k_steps: int,
    best: str | None,
    written: str | None,
    title: str = "Thrust-model identification (validation data)",
    scores: Mapping[str, SelectionScore] | None = None,
) -> Table:
    """Table 1: Fit% of the k-step prediction and of simulation, FPE, MSE per structure, and
    with ``scores`` the selection figures: steady-state (DC) error against the static fit,
    stability, simulated-thrust RMSE at steady state and in transients.

    ``best`` (highest k-step Fit%) is marked with ``*``; ``written`` (the model saved to the
    output file) with ``->``. A failed structure shows its error instead of numbers.
    """
    scores = scores or {}
    table = Table(title=title)
    table.add_column("", no_wrap=True)
    table.add_column("Structure")
    table.add_column("Orders")
    table.add_column(f"Fit% {k_steps}-step", justify="right")
    table.add_column("Fit% sim", justify="right")
    table.add_column(escape("FPE [N^2]"), justify="right")
    table.add_column(escape("MSE [N^2]"), justify="right")
    if scores:
        table.add_column("DC err %", justify="right")
        table.add_column(escape("RMSE steady [N]"), justify="right")
        table.add_column(escape("RMSE trans. [N]"), justify="right")
        table.add_column("admitted")
    for result in results:
        mark = " ".join(
            m
            for m, name in ((BEST_MARK, best), (WRITTEN_MARK, written))
            if name == result.structure
        )
        if not result.ok:
            failure = f"[red]failed: {escape(str(result.error))}[/red]"
            table.add_row(mark, result.structure, failure, *["-"] * (8 if scores else 4))
            continue
        metrics = result.metrics
        cells = [
            f"{metrics.fit_prediction_pct:.2f}",
            f"{metrics.fit_simulation_pct:.2f}",
            f"{metrics.fpe_n2:.4g}",
            f"{metrics.mse_n2:.4g}",
        ]
        if scores:
            s = scores[result.structure]
            admitted = "yes" if s.admitted() else ("unstable" if not s.stable else "DC off")
            cells += [
                f"{s.dc_error_pct:.2f}",
                f"{s.steady_rmse_n:.3f}",
                f"{s.transient_rmse_n:.3f}",
                admitted,
            ]
        table.add_row(mark, result.structure, result.model.orders, *cells)
    table.caption = (
        f"{BEST_MARK} best {k_steps}-step-ahead Fit% (Table 1's criterion); "
        f"{WRITTEN_MARK} written model (unless chosen with --write: the admitted one with the "
        "smallest RMS of the steady and transient errors of thrust simulated from PWM alone; a "
        f"dynamic model is admitted when stable and within {DC_TOLERANCE_PCT:g} % of the static "
        "fit at steady state). FPE and MSE: one-step errors on the estimation data."
    )
    return table


def plot_validation(
    path: str | Path, results: Sequence[StructureResult], validation: IdData, k_steps: int
) -> None:
    """Save a figure of measured vs simulated and k-step-predicted thrust on validation data.

    Raises
    ------
    InputError
        When matplotlib (the ``plot`` extra) is not installed or the file cannot be written.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise InputError("--plot needs matplotlib: pip install 'tether-companion[plot]'") from None
    ok = [r for r in results if r.ok]
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(11, 7))
    t = validation.time_s
    for ax, label in zip(axes, ("simulation", f"{k_steps}-step prediction"), strict=True):
        ax.plot(t, validation.thrust_n, color="black", linewidth=1.5, label="measured")
        for result in ok:
            predicted = (
                result.model.simulate(validation)
                if label == "simulation"
                else result.model.predict(validation, k_steps)
            )
            ax.plot(t, predicted, linewidth=0.8, label=result.structure)
        ax.set_ylabel("total thrust [N]")
        ax.set_title(label)
        ax.legend(loc="upper right", ncol=4, fontsize="small")
    axes[-1].set_xlabel("flight-controller time [s]")
    fig.tight_layout()
    try:
        fig.savefig(path)
    except OSError as exc:
        raise InputError(f"{path}: cannot write the plot ({exc.strerror})") from None
    finally:
        plt.close(fig)

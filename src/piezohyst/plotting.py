"""Figures, drawn with matplotlib's object API (no pyplot state, no screen needed).

Units are in the axis labels.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ._validation import FloatArray

__all__ = ["Curve", "loop_figure", "save_grid", "save_panels"]

Curve = tuple[FloatArray, FloatArray, str, dict[str, object]]


def loop_figure(
    ax: Axes,
    curves: Sequence[Curve],
    *,
    xlabel: str,
    ylabel: str,
    title: str,
    identity: bool = False,
) -> None:
    """Draw input-output curves on ``ax`` (one line each, with a legend)."""
    for x, y, label, style in curves:
        ax.plot(x, y, label=label, **style)  # type: ignore[arg-type]
    if identity:
        lo = min(float(np.min(c[0])) for c in curves)
        hi = max(float(np.max(c[0])) for c in curves)
        ax.plot([lo, hi], [lo, hi], color="0.4", lw=0.8, ls=":", label="ideal (y = x)")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=8, loc="best")


def save_panels(path: Path, panels: Sequence[dict[str, object]], *, suptitle: str) -> Path:
    """One figure with side-by-side panels, each given as ``loop_figure`` keywords."""
    fig = Figure(figsize=(5.2 * len(panels), 4.2))
    axes = fig.subplots(1, len(panels), squeeze=False)
    for ax, panel in zip(axes[0], panels, strict=True):
        loop_figure(ax, **panel)  # type: ignore[arg-type]
    fig.suptitle(suptitle, fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def save_grid(
    path: Path,
    rows: Sequence[Sequence[dict[str, object]]],
    *,
    suptitle: str,
    height_ratios: Sequence[float] | None = None,
) -> Path:
    """One figure with rows of panels (e.g. loops above, residuals below).

    Parameters
    ----------
    path : Path
        The PNG to write.
    rows : sequence of sequences of dict
        Each panel as ``loop_figure`` keywords; every row has the same length.
    suptitle : str
    height_ratios : sequence of float, optional
        Relative row heights.

    Returns
    -------
    Path
    """
    n_rows, n_cols = len(rows), len(rows[0])
    ratios = list(height_ratios) if height_ratios is not None else [1.0] * n_rows
    fig = Figure(figsize=(5.2 * n_cols, 2.1 * sum(ratios) + 0.8))
    axes = fig.subplots(n_rows, n_cols, squeeze=False, height_ratios=ratios)
    for row_axes, row in zip(axes, rows, strict=True):
        for ax, panel in zip(row_axes, row, strict=True):
            loop_figure(ax, **panel)  # type: ignore[arg-type]
    fig.suptitle(suptitle, fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path

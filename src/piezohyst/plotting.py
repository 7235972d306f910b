"""Figures, drawn with matplotlib's object API (no pyplot state, no screen needed).

Units are in the axis labels.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import ArrayLike

from ._validation import FloatArray, as_signal, as_time, same_length

__all__ = ["Curve", "fit_figure", "loop_figure", "model_figure", "save_grid", "save_panels"]

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
    """Draw input-output curves on ``ax`` (one line each, with a legend).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where to draw.
    curves : sequence of Curve
        ``(x, y, label, style)`` per line, ``style`` the keywords of ``ax.plot``.
    xlabel, ylabel, title : str
        The axes' labels and title.
    identity : bool, default False
        Also draw the line y = x (an ideal compensation), over the curves' x range.
    """
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
    """One figure with side-by-side panels, each given as ``loop_figure`` keywords.

    Parameters
    ----------
    path : Path
        The image file to write (its suffix names the format).
    panels : sequence of dict
        One panel each: the keywords of :func:`loop_figure` but ``ax``.
    suptitle : str
        The figure's title.

    Returns
    -------
    Path
        ``path``, written.
    """
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


def fit_figure(
    x: FloatArray,
    y: FloatArray,
    predicted: FloatArray,
    t: FloatArray | None,
    *,
    units: tuple[str, str] = ("V", "C"),
    title: str = "",
) -> Figure:
    """A model against a record: the loop, the output over time, the residual.

    Parameters
    ----------
    x, y, predicted : ndarray
        Input, measured and modelled output.
    t : ndarray or None
        Times (s); sample numbers without them.
    units : (str, str)
        Input and output units, for the labels.
    title : str

    Returns
    -------
    matplotlib.figure.Figure
        Not shown, not saved: ``fig.savefig(...)``, or a notebook displays it.
    """
    time = np.arange(x.size, dtype=np.float64) if t is None else t
    tlabel = "sample" if t is None else "time (s)"
    in_u, out_u = units
    measured = {"color": "0.55", "lw": 1.6}
    model = {"color": "C0", "lw": 1.0, "ls": "--"}
    fig = Figure(figsize=(11.0, 4.6))
    grid = fig.add_gridspec(2, 2, height_ratios=[2.0, 1.0])
    loop_figure(fig.add_subplot(grid[:, 0]),
                [(x, y, "measured", measured), (x, predicted, "model", model)],
                xlabel=f"input ({in_u})", ylabel=f"output ({out_u})", title="loop")  # fmt: skip
    err = y - predicted
    loop_figure(fig.add_subplot(grid[0, 1]),
                [(time, y, "measured", measured), (time, predicted, "model", model)],
                xlabel=tlabel, ylabel=f"output ({out_u})", title="over time")  # fmt: skip
    span = max(float(np.ptp(y)), 1e-300)
    nrmse = float(np.sqrt(np.mean(err * err))) / span
    loop_figure(fig.add_subplot(grid[1, 1]),
                [(time, err, "measured - model", {"lw": 0.7, "color": "C3"})],
                xlabel=tlabel, ylabel=f"residual ({out_u})",
                title=f"residual, NRMSE {100 * nrmse:.3g} %")  # fmt: skip
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig


def model_figure(model: Any, x: ArrayLike, y: ArrayLike, t: ArrayLike | None = None) -> Figure:
    """A fitted model against a record (``model.plot``): see :func:`fit_figure`.

    Parameters
    ----------
    model : HysteresisModel
    x, y : array_like
    t : array_like, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    xs, ys = as_signal(x, "x"), as_signal(y, "y")
    same_length(xs, ys, "x", "y")
    ts = None if t is None else as_time(t, xs.size, required=False, owner="plot")
    return fit_figure(xs, ys, model.predict(xs, ts), ts,
                      units=(model.input_unit, model.output_unit),
                      title=f"{type(model).__name__}: {model.operator_.summary}")  # fmt: skip

"""A report a lab can file: one self-contained HTML page, Markdown and JSON.

Everything needed to trace a number back: date, piezohyst version, the
command line, the data file's name, size and SHA-256, the time window, the
model's settings, thresholds and units, and every metric with its unit.
Figures use SI prefixes (µC, not 1e−6) and keep the data visible: the model is
drawn dashed over it, with the residual in its own panel below.
"""

from __future__ import annotations

import base64
import hashlib
import html
import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._version import __version__
from ..io import atomic_write, atomic_write_text

__all__ = ["Figure", "Metric", "Report", "file_facts", "si_scale"]

_PREFIXES = [(9, "G"), (6, "M"), (3, "k"), (0, ""), (-3, "m"), (-6, "µ"), (-9, "n"),
             (-12, "p"), (-15, "f")]  # fmt: skip
_SI = {"C", "V", "m", "s", "A", "S", "F"}


def si_scale(values: ArrayLike, unit: str) -> tuple[float, str]:
    """A factor and prefixed unit that bring ``values`` to 1..1000 (``C`` -> ``µC``).

    Parameters
    ----------
    values : array_like
        The data to show.
    unit : str
        Their unit; only plain SI units (C, V, m, s, A, S, F) get a prefix.

    Returns
    -------
    tuple
        Multiply the values by the factor to plot them in the returned unit.

    Examples
    --------
    >>> si_scale([2e-7, 3e-7], "C"), si_scale([4e-6], "m"), si_scale([140.0], "V")
    ((1000000000.0, 'nC'), (1000000.0, 'µm'), (1.0, 'V'))
    """
    arr = np.asarray(values, dtype=np.float64)
    peak = float(np.max(np.abs(arr))) if arr.size else 0.0
    if unit not in _SI or peak == 0.0 or not math.isfinite(peak):
        return 1.0, unit
    for exponent, prefix in _PREFIXES:
        if peak >= 10.0**exponent * 0.999:
            return 10.0 ** (-exponent), prefix + unit
    exponent, prefix = _PREFIXES[-1]
    return 10.0 ** (-exponent), prefix + unit


def _number(value: float, unit: str) -> str:
    """A value with an SI prefix: 4.3e-9 C -> '4.3 nC'."""
    if not math.isfinite(value):
        return f"{value} {unit}".strip()
    factor, shown = si_scale([value], unit)
    return f"{value * factor:.4g} {shown}".strip()


@dataclass(frozen=True)
class Metric:
    """One reported quantity.

    Attributes
    ----------
    key : str
        Machine name (JSON).
    label : str
        What a reader sees.
    value : float or int or str
        The value.
    unit : str
        Its unit ("" for counts, "%" for percentages).
    """

    key: str
    label: str
    value: float | int | str
    unit: str = ""

    def text(self) -> str:
        """The value with its unit for people (SI prefixes).

        Returns
        -------
        str
        """
        if isinstance(self.value, float) and self.unit not in ("", "%"):
            return _number(self.value, self.unit)
        if isinstance(self.value, float):
            return f"{self.value:.4g} {self.unit}".strip()
        return f"{self.value} {self.unit}".strip()


@dataclass(frozen=True)
class Figure:
    """A saved figure and its caption.

    Attributes
    ----------
    path : Path
    caption : str
    """

    path: Path
    caption: str


def file_facts(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Name, size and SHA-256 of a file, so a report names exactly what it measured.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict
        ``name``, ``path``, ``bytes``, ``sha256``.
    """
    p = Path(path)
    digest = hashlib.sha256()
    with open(p, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return {"name": p.name, "path": str(p), "bytes": p.stat().st_size, "sha256": digest.hexdigest()}


@dataclass
class Report:
    """Collects metadata, metrics and figures, then writes HTML, Markdown and JSON.

    Parameters
    ----------
    title : str
        The report's heading.
    folder : Path
        Where the files go.
    """

    title: str
    folder: Path
    metadata: dict[str, Any] = field(default_factory=dict)
    metrics: list[Metric] = field(default_factory=list)
    figures: list[Figure] = field(default_factory=list)
    tables: dict[str, list[tuple[str, str]]] = field(default_factory=dict)

    def add(self, key: str, label: str, value: float | int | str, unit: str = "") -> None:
        """Add one metric.

        Parameters
        ----------
        key, label : str
            Machine name and what a reader sees.
        value : float, int or str
        unit : str
        """
        self.metrics.append(Metric(key, label, value, unit))

    def figure(
        self,
        name: str,
        caption: str,
        panels: Sequence[dict[str, Any]],
        *,
        stacked: bool = False,
    ) -> Path:
        """Draw and save a figure of one or more panels.

        Parameters
        ----------
        name : str
            File name (``.png``).
        caption : str
            Shown under it in the report.
        panels : sequence of dict
            Each: ``curves`` [(x, y, label, style)], ``xunit``, ``yunit``,
            ``xlabel``, ``ylabel`` (quantity names), ``title``, ``xscale``,
            ``yscale`` ("linear", "log"); units are given SI prefixes and put in
            the axis labels.
        stacked : bool
            Panels above each other sharing the x axis (a signal and its
            residual), instead of side by side.

        Returns
        -------
        Path
        """
        from matplotlib.figure import Figure as MplFigure

        n = len(panels)
        if stacked:
            fig = MplFigure(figsize=(7.5, 2.4 + 2.0 * n))
            axes = fig.subplots(n, 1, sharex=True, squeeze=False, height_ratios=[2] + [1] * (n - 1))
            axes_list = list(axes[:, 0])
        else:
            fig = MplFigure(figsize=(5.2 * n, 4.2))
            axes_list = list(fig.subplots(1, n, squeeze=False)[0])
        for ax, panel in zip(axes_list, panels, strict=True):
            curves = panel["curves"]
            xs = np.concatenate([np.asarray(c[0]) for c in curves])
            ys = np.concatenate([np.asarray(c[1]) for c in curves])
            fx, xunit = si_scale(xs, panel.get("xunit", ""))
            fy, yunit = si_scale(ys, panel.get("yunit", ""))
            for x, y, label, style in curves:
                ax.plot(np.asarray(x) * fx, np.asarray(y) * fy, label=label, **style)
            if not stacked or ax is axes_list[-1]:
                ax.set_xlabel(f"{panel['xlabel']} ({xunit})" if xunit else panel["xlabel"])
            ax.set_ylabel(f"{panel['ylabel']} ({yunit})" if yunit else panel["ylabel"])
            ax.set_xscale(panel.get("xscale", "linear"))
            ax.set_yscale(panel.get("yscale", "linear"))
            ax.set_title(panel.get("title", ""), fontsize=10)
            ax.grid(True, lw=0.3)
            ax.legend(fontsize=8, loc="best")
        fig.tight_layout()  # the caption goes under the figure in the report, not into it
        path = self.folder / name

        def save(tmp: Path) -> None:
            fig.savefig(tmp, dpi=110, format="png")

        atomic_write(path, save)
        self.figures.append(Figure(path, caption))
        return path

    # ---------------------------------------------------------------- output
    def as_dict(self) -> dict[str, Any]:
        """Everything in the report as JSON-ready data.

        Returns
        -------
        dict
        """
        return {
            "title": self.title,
            "piezohyst_version": __version__,
            **self.metadata,
            "metrics": {m.key: {"value": m.value, "unit": m.unit} for m in self.metrics},
            "tables": {k: dict(v) for k, v in self.tables.items()},
            "figures": [f.path.name for f in self.figures],
        }

    def write(self) -> list[Path]:
        """Write ``metrics.json``, ``report.md`` and ``report.html`` into the folder.

        Returns
        -------
        list of Path
            The figures and the three files.
        """
        data = self.as_dict()
        json_path = atomic_write_text(
            self.folder / "metrics.json", json.dumps(data, indent=2, default=str) + "\n"
        )
        md_path = atomic_write_text(self.folder / "report.md", self._markdown())
        html_path = atomic_write_text(self.folder / "report.html", self._html())
        return [*(f.path for f in self.figures), json_path, md_path, html_path]

    def _rows(self) -> list[tuple[str, list[tuple[str, str]]]]:
        meta = [("piezohyst version", __version__)]
        meta += [(k.replace("_", " "), _plain(v)) for k, v in self.metadata.items()]
        sections = [("Results", [(m.label, m.text()) for m in self.metrics]), ("Provenance", meta)]
        return sections + list(self.tables.items())

    def _markdown(self) -> str:
        lines = [f"# {self.title}", ""]
        for heading, rows in self._rows():
            lines += [f"## {heading}", "", "| quantity | value |", "|---|---|"]
            lines += [f"| {k} | {v} |" for k, v in rows]
            lines.append("")
        for fig in self.figures:
            lines += [f"![{fig.caption}]({fig.path.name})", "", f"*{fig.caption}*", ""]
        return "\n".join(lines)

    def _html(self) -> str:
        parts = [
            "<!doctype html>",
            '<html lang="en"><head><meta charset="utf-8">',
            f'<meta name="generator" content="piezohyst {__version__}">',
            f"<title>{html.escape(self.title)}</title>",
            "<style>body{font-family:sans-serif;max-width:62em;margin:2em auto;padding:0 1em}"
            "table{border-collapse:collapse;margin-bottom:1.5em}"
            "td,th{border:1px solid #bbb;padding:.25em .6em;text-align:left;vertical-align:top}"
            "td.v{font-family:monospace}figure{margin:1.5em 0}img{max-width:100%}</style>",
            "</head><body>",
            f"<h1>{html.escape(self.title)}</h1>",
        ]
        for heading, rows in self._rows():
            parts.append(f"<h2>{html.escape(heading)}</h2><table>")
            parts += [
                f'<tr><th>{html.escape(k)}</th><td class="v">{html.escape(v)}</td></tr>'
                for k, v in rows
            ]
            parts.append("</table>")
        for fig in self.figures:
            encoded = base64.b64encode(fig.path.read_bytes()).decode("ascii")
            parts.append(
                f'<figure><img alt="{html.escape(fig.caption)}" '
                f'src="data:image/png;base64,{encoded}">'
                f"<figcaption>{html.escape(fig.caption)}</figcaption></figure>"
            )
        parts.append("</body></html>")
        return "\n".join(parts) + "\n"


def _plain(value: Any) -> str:
    if isinstance(value, dict):
        return ", ".join(f"{k}: {_plain(v)}" for k, v in value.items())
    if isinstance(value, list | tuple):
        return ", ".join(_plain(v) for v in value)
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)

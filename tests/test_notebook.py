"""In a notebook: a fitted model draws itself against a record and shows as a table."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

import piezohyst as ph


def test_plot_draws_loop_time_and_residual() -> None:
    rec = ph.simulate(duration=4.0)
    model = ph.ActivePI(8).fit(rec.voltage, rec.charge, t=rec.t)
    fig = model.plot(rec.voltage, rec.charge, t=rec.t)
    assert isinstance(fig, Figure)
    loop, over_time, residual = fig.axes
    assert [ln.get_label() for ln in loop.get_lines()] == ["measured", "model"]
    drawn = residual.get_lines()[0].get_ydata()
    np.testing.assert_array_equal(drawn, rec.charge - model.predict(rec.voltage, t=rec.t))
    assert "NRMSE" in residual.get_title() and over_time.get_xlabel() == "time (s)"


def test_a_model_shows_as_a_table() -> None:
    rec = ph.simulate(duration=4.0)
    html = ph.ActivePI(8).fit(rec.voltage, rec.charge, t=rec.t)._repr_html_()
    for cell in ("<table>", "ActivePI", "fit NRMSE", "integral", "training window", "C/(V*s)"):
        assert cell in html, cell
    assert "fitted</th><td>no" in ph.PreisachModel()._repr_html_()

"""Analysis: comparing models, choosing one, reports.
May import: the foundation, ``_kernels``, ``io``, ``model`` (never ``control``).

Comparing models on held-out data (``comparison``)
    compare_models, Comparison, ComparisonRow
Choosing one inside a record, with how sure the choice is (``selection``; what the record's
input tells it, in ``turns``)
    select_model, Selection, SelectionRow
A model's report: its numbers and figures (``report``)
    Report
A record's own frequency response from several inputs, without a model (``response``)
    measured_response, MeasuredResponse
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import attach

# each name loaded from its module at first use (PEP 562): importing the package stays light
__getattr__, __dir__ = attach(
    __name__,
    {
        "Comparison": ".comparison",
        "ComparisonRow": ".comparison",
        "compare_models": ".comparison",
        "MeasuredResponse": ".response",
        "Report": ".report",
        "Selection": ".selection",
        "SelectionRow": ".selection",
        "measured_response": ".response",
        "select_model": ".selection",
    },
)

if TYPE_CHECKING:  # the same names, for type checkers and editors
    from .comparison import Comparison, ComparisonRow, compare_models
    from .report import Report
    from .response import MeasuredResponse, measured_response
    from .selection import Selection, SelectionRow, select_model

__all__ = [
    "Comparison",
    "ComparisonRow",
    "MeasuredResponse",
    "Report",
    "Selection",
    "SelectionRow",
    "compare_models",
    "measured_response",
    "select_model",
]

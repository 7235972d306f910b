"""What every preset shares: the settings every one ends with (a dataclass: its fields are
the presets' keyword arguments, stored as given, the scikit-learn contract) and the growth
terms by name, with the subsets to choose from."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

from ..._validation import FloatArray
from ..estimator import (
    GROWTH_TERMS,
)
from ..terms import Term, make_term

__all__ = ["Common", "growth_terms_to_fit"]


# Each preset is a dataclass (``eq=False, repr=False``: the model class's own ``repr`` and
# identity kept): its ``__init__`` is written from its fields, each argument stored as given
# and nothing else, as the scikit-learn contract asks
@dataclass(eq=False, repr=False, kw_only=True)
class Common:
    """The keyword arguments every preset ends with (see :class:`~piezohyst.HysteresisModel`)."""

    input_unit: str = "V"
    output_unit: str = "C"
    input_dynamics: str = "none"
    output_dynamics: str = "none"


def growth_terms_to_fit(
    fixed: list[Term], names: tuple[str, ...] | None, x_range: FloatArray
) -> tuple[list[Term], list[tuple[int, ...]] | None]:
    """Kept terms, then growth terms by name (the term registry); ``names`` None: all of
    them, with every physical subset to choose from (the kept terms in each)."""
    auto = names is None
    chosen = GROWTH_TERMS if names is None else names
    terms = fixed + [make_term(name).bind(x_range) for name in chosen]
    if not auto:
        return terms, None
    base = tuple(range(len(fixed)))
    growth = range(len(fixed), len(terms))
    kind = {j: terms[j].kind for j in growth}

    def physical(combo: tuple[int, ...]) -> bool:
        """A conductance that rises with the voltage (``abs_integral``) presupposes the
        conductance itself (``integral``): on a record of one polarity the two columns nearly
        coincide, and the rise alone fits it as well by chance, not by physics."""
        names = {kind[j] for j in combo}
        return "abs_integral" not in names or "integral" in names or "integral" not in chosen

    subsets = [base + combo for size in range(len(chosen) + 1)
               for combo in itertools.combinations(growth, size) if physical(combo)]  # fmt: skip
    return terms, subsets

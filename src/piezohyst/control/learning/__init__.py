"""Learning a repeated scan (iterative learning control): the learning compensator and the
parts it is made of.

===============  =========================================================================
module           what it holds
===============  =========================================================================
``compensator``  :class:`LearningCompensator` (command a trial, learn from its readings),
                 :class:`Trial` (what one trial did), :func:`resolved_law`
``design``       the harmonic law's design: :func:`design_learning`, :class:`LearningDesign`
``jacobian``     the Jacobian law's step through the model's sensitivity
``laws``         the laws behind one interface (:class:`~.laws.Law`): ``"harmonic"``,
                 ``"jacobian"``, by name in :data:`~.laws.LAWS`
``probe``        the lead-in's probe: small sines whose response measures the loop's timing
``trial``        a trial's trajectory, its limits, the slew and anti-windup
===============  =========================================================================
"""

from .compensator import LearningCompensator, Trial, resolved_law
from .design import LearningDesign, design_learning

__all__ = ["LearningCompensator", "LearningDesign", "Trial", "design_learning", "resolved_law"]

"""Learning a repeated scan (iterative learning control): the learning compensator and the
parts it is made of.

==================  =========================================================================
module              what it holds
==================  =========================================================================
``compensator``     :class:`LearningCompensator` (command a trial, learn from its readings),
                    :func:`resolved_law`
``coupled``         :class:`CoupledLearningCompensator`: a coupled stage's scan, the coupling's
                    inverse and one learner per actuator
``coupled_saving``  the coupled learner's state as a file, resumed exactly
``design``          the harmonic law's design: :func:`design_learning`, :class:`LearningDesign`
``harmonics``       each harmonic's response measured between trials, learned through where
                    the model's would grow the error (a misplaced mode)
``jacobian``        the Jacobian law's step through the model's sensitivity
``laws``            the laws behind one interface (:class:`~.laws.Law`): ``"harmonic"``,
                    ``"jacobian"``, by name in :data:`~.laws.LAWS`
``probe``           the lead-in's probe: small sines whose response measures the loop's timing
``safety``          when a trial's error says to undo learning (rollbacks), and the warning
``saving``          a learner's state as a file, resumed exactly
``stepping``        ``step`` and ``process``: the learner in a loop that reads each sample
``timing``          the loop's lag measured on the first trial learned from, where the model
                    holds none
``trial``           :class:`Trial` (what one trial did), :class:`CoupledTrial` (a stage's); a
                    trial's trajectory, its limits, the slew and anti-windup
==================  =========================================================================
"""

from .compensator import LearningCompensator, resolved_law
from .coupled import CoupledLearningCompensator, CoupledTrial
from .design import LearningDesign, design_learning
from .trial import Trial

__all__ = [
    "CoupledLearningCompensator",
    "CoupledTrial",
    "LearningCompensator",
    "LearningDesign",
    "Trial",
    "design_learning",
    "resolved_law",
]

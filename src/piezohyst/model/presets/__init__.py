r"""The public models: thin constructors over the one model class.

Each preset names its core, declares its own settings (with one rule each)
and the terms it fits; everything else — fit, propagate, states, growth,
inversion, files — is :class:`~piezohyst.model.HysteresisModel`'s:

======================  ======================================================
:class:`ClassicalPI`     play operators alone (eq. 11-12)
:class:`ActivePI`        play operators plus the paper's integral (eq. 13-16)
:class:`GeneralizedPI`   play operators plus asymmetry, creep and chosen growth terms
:class:`PIModel`         play operators plus any terms, custom ones included
:class:`PreisachModel`   a Preisach density plus growth (and relaxation) terms
:class:`DuhemModel`      Duhem slopes plus growth terms
:class:`BoucWenModel`    the Bouc-Wen equation plus growth terms
======================  ======================================================

The play-operator presets are in ``play``, the packed cores' in ``packed``.
"""

from ..estimator import GROWTH_TERMS
from ..inverse_spec import InverseSpec
from ..model import HysteresisModel
from ..persistence import model_class, model_names
from ..state import History, ModelState
from .packed import BoucWenModel, DuhemModel, PreisachModel
from .play import ActivePI, ClassicalPI, GeneralizedPI, PIModel

__all__ = [
    "GROWTH_TERMS",
    "ActivePI",
    "BoucWenModel",
    "ClassicalPI",
    "DuhemModel",
    "GeneralizedPI",
    "History",
    "HysteresisModel",
    "InverseSpec",
    "ModelState",
    "PIModel",
    "PreisachModel",
    "model_class",
    "model_names",
]

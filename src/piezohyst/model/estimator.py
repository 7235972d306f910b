"""The estimator contract every model follows, and the rules for its settings.

:class:`Estimator` is the scikit-learn contract without inheriting from
scikit-learn: ``__init__`` only stores its arguments; ``get_params`` /
``set_params`` are read from ``__init__``'s signature (so
``sklearn.base.clone`` works); every setting has one rule, declared once per
class (``_rules``), merged along the class hierarchy and applied by
:meth:`Estimator.check_params` before any work; settings travel to and from
model files as plain JSON.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence
from typing import Any, ClassVar, Self

import numpy as np

from .._validation import FloatArray, as_signal, check_float, check_int
from ..errors import ParameterError
from .cores.base import Core, core_class
from .dynamics import KINDS as DYNAMICS_KINDS
from .terms import Creep, Term, growth_kinds, make_term

__all__ = ["GROWTH_TERMS", "Estimator", "Params", "Rule", "SeveralChannels"]

#: The growth terms "auto" chooses among (any registered growth term can be named)
GROWTH_TERMS = ("integral", "time", "abs_integral")


# ------------------------------------------------------------ parameter rules
# A rule checks one constructor argument and returns the value to use; every
# model declares its rules once (``_rules``), merged along the class hierarchy,
# and ``fit`` applies all of them before any work. A test requires a rule for
# every constructor argument.
Rule = Callable[[Any, str, str], Any]


def _unit(value: object, name: str, owner: str) -> str:
    if not isinstance(value, str) or not value:
        msg = f"The '{name}' parameter of {owner} must be a non-empty str. Got {value!r} instead."
        raise ParameterError(msg)
    return value


def _int_in(low: int, high: int) -> Rule:
    def rule(value: object, name: str, owner: str) -> int:
        return check_int(value, name, owner, low, high)

    return rule


def _min_slope(value: object, name: str, owner: str) -> float:
    return check_float(value, name, owner, 0.0, 1.0, low_open=True)


def _bool(value: object, name: str, owner: str) -> bool:
    if not isinstance(value, bool):
        msg = f"The '{name}' parameter of {owner} must be True or False. Got {value!r} instead."
        raise ParameterError(msg)
    return value


def _thresholds(value: object, name: str, owner: str) -> FloatArray | None:
    if value is None:
        return None
    try:
        thr = as_signal(value, name)  # type: ignore[arg-type]
    except ValueError:
        thr = np.array([np.nan])
    if (
        thr.size > 1000
        or not np.all(np.isfinite(thr))
        or thr[0] != 0.0
        or (thr.size > 1 and np.any(np.diff(thr) <= 0))
    ):
        msg = (
            f"The '{name}' parameter of {owner} must be 1 to 1000 strictly increasing "
            f"values starting at 0. Got {thr.tolist()[:8]}{'...' if thr.size > 8 else ''}."
        )
        raise ParameterError(msg)
    return thr


def _growth_terms(value: object, name: str, owner: str) -> tuple[str, ...] | None:
    """None for 'auto' (choose among the built-in ones), else distinct registered growth
    terms, in the registry's order (:func:`~piezohyst.model.terms.growth_kinds`); 'domain' is
    the record's: the charge's leakage (``integral``, and ``abs_integral`` where the record's
    holds show its rise), none on a displacement record (see
    :func:`~piezohyst.model.fit_record.identify_model`)."""
    kinds = growth_kinds()
    if isinstance(value, str):
        if value == "domain":
            return ("integral",)
        if value != "auto":
            msg = (
                f"The '{name}' parameter of {owner} must be 'domain', 'auto' or a sequence "
                f"of {list(kinds)}. Got {value!r} instead."
            )
            raise ParameterError(msg)
        return None
    terms = tuple(value) if isinstance(value, Sequence) else (value,)
    if any(term not in kinds for term in terms) or len(set(terms)) != len(terms):
        msg = (
            f"The '{name}' parameter of {owner} must hold distinct terms from "
            f"{list(kinds)}. Got {list(terms)!r} instead."
        )
        raise ParameterError(msg)
    return tuple(t for t in kinds if t in terms)


def _creep(value: object, name: str, owner: str) -> Creep | None:
    if isinstance(value, Sequence) and not isinstance(value, str):
        if len(value) == 0:
            return None
        try:
            return Creep(value)
        except ParameterError:
            pass
    msg = (
        f"The '{name}' parameter of {owner} must be up to 20 positive time "
        f"constants in s. Got {value!r} instead."
    )
    raise ParameterError(msg)


def _dynamics_kind(value: object, name: str, owner: str) -> str:
    choices = (*DYNAMICS_KINDS, "auto")
    if value not in choices:
        msg = f"The '{name}' parameter of {owner} must be one of {choices}. Got {value!r} instead."
        raise ParameterError(msg)
    return str(value)


def _output_kind(value: object, name: str, owner: str) -> str:
    if value not in ("none", "second-order"):
        msg = (
            f"The '{name}' parameter of {owner} must be 'none' or 'second-order'. "
            f"Got {value!r} instead."
        )
        raise ParameterError(msg)
    return str(value)


def _terms(value: object, name: str, owner: str) -> tuple[Term, ...]:
    if isinstance(value, str | Term) or not isinstance(value, Sequence):
        msg = (
            f"The '{name}' parameter of {owner} must be a sequence of term kinds or Term "
            f"instances. Got {value!r} instead."
        )
        raise ParameterError(msg)
    terms = tuple(make_term(spec) for spec in value)
    kinds = [term.kind for term in terms]
    if len(set(kinds)) != len(kinds):
        msg = f"The '{name}' parameter of {owner} must not repeat a kind. Got {kinds!r}."
        raise ParameterError(msg)
    return terms


def _core_rule(value: object, name: str, owner: str) -> type[Core]:
    if isinstance(value, str):
        found = core_class(value)
        if found is not None:
            return found
    elif isinstance(value, type) and issubclass(value, Core) and value.kind:
        return value
    msg = (
        f"The '{name}' parameter of {owner} must be a registered core (a Core subclass with a "
        f"kind, or one of its names). Got {value!r} instead."
    )
    raise ParameterError(msg)


def _settings_rule(value: object, name: str, owner: str) -> dict[str, Any]:
    if value is None:
        return {}
    if isinstance(value, dict) and all(isinstance(k, str) for k in value):
        return dict(value)
    msg = f"The '{name}' parameter of {owner} must be None or a dict of settings. Got {value!r}."
    raise ParameterError(msg)


class Params:
    """scikit-learn's ``get_params`` and ``set_params``, read from ``__init__``'s signature,
    and a ``repr`` of the settings that differ from their defaults: every estimator here."""

    @classmethod
    def _param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [p.name for p in sig.parameters.values() if p.name != "self"]

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The constructor arguments, as given (scikit-learn's contract).

        Parameters
        ----------
        deep : bool, default True
            Accepted for scikit-learn; a model holds no sub-estimators.

        Returns
        -------
        dict
            Name to value, read from ``__init__``'s signature.
        """
        return {name: getattr(self, name) for name in self._param_names()}

    def set_params(self, **params: Any) -> Self:
        """Set constructor arguments (scikit-learn's contract); checked at the next ``fit``.

        Parameters
        ----------
        **params
            Names from :meth:`get_params`; any other name raises.

        Returns
        -------
        object
            ``self``.
        """
        valid = self._param_names()
        for name, value in params.items():
            if name not in valid:
                msg = (
                    f"Invalid parameter {name!r} for {type(self).__name__}. "
                    f"Valid parameters are: {valid}."
                )
                raise ParameterError(msg)
            setattr(self, name, value)
        return self

    def __repr__(self) -> str:
        sig = inspect.signature(type(self).__init__)
        shown = [
            f"{k}={v!r}"
            for k, v in self.get_params().items()
            if not _same(v, sig.parameters[k].default)
        ]
        return f"{type(self).__name__}({', '.join(shown)})"


class SeveralChannels(Params):
    """scikit-learn's view of a model of several inputs and outputs (a stage, a structure):
    a regressor of 2-D inputs and outputs, fitted once ``_fitted`` is set."""

    _fitted: ClassVar[str] = ""

    def __sklearn_tags__(self) -> Any:
        """scikit-learn's tags: a regressor of (samples, inputs) to (samples, outputs)."""
        from sklearn.utils import InputTags, RegressorTags, Tags, TargetTags

        return Tags(
            estimator_type="regressor",
            target_tags=TargetTags(required=True, multi_output=True, single_output=False),
            regressor_tags=RegressorTags(),
            input_tags=InputTags(two_d_array=True),
        )

    def __sklearn_is_fitted__(self) -> bool:
        """Whether :meth:`fit` has run (scikit-learn's ``check_is_fitted`` asks this)."""
        return hasattr(self, self._fitted)


class Estimator(Params):
    """The scikit-learn estimator contract and the settings' rules (see the module)."""

    _rules: ClassVar[dict[str, Rule]] = {}

    def __sklearn_tags__(self) -> Any:
        """scikit-learn's tags (1.6 and later ask for them, ``check_is_fitted`` too): a
        regressor of one input signal, its sample times as ``t``. Imported only here:
        scikit-learn calls this, so it is there when it runs."""
        from sklearn.utils import InputTags, RegressorTags, Tags, TargetTags

        return Tags(
            estimator_type="regressor",
            target_tags=TargetTags(required=True, one_d_labels=True),
            regressor_tags=RegressorTags(),
            input_tags=InputTags(one_d_array=True, two_d_array=False),
        )

    def __sklearn_is_fitted__(self) -> bool:
        """Whether :meth:`fit` has run (scikit-learn's ``check_is_fitted`` asks this)."""
        return hasattr(self, "operator_")

    @classmethod
    def parameter_rules(cls) -> dict[str, Rule]:
        """Every constructor argument's rule, declared once per class along its hierarchy.

        Returns
        -------
        dict
            Argument name to a function ``rule(value, name, owner)`` that
            returns the checked value or raises :class:`ParameterError`.
        """
        rules: dict[str, Rule] = {}
        for klass in reversed(cls.__mro__):
            rules.update(vars(klass).get("_rules", {}))
        names = set(cls._param_names())
        return {name: rule for name, rule in rules.items() if name in names}

    def check_params(self) -> dict[str, Any]:
        """Apply every parameter rule (in ``__init__`` order), as ``fit`` does first.

        Returns
        -------
        dict
            The checked values by name.

        Raises
        ------
        ParameterError
            Naming the first argument that breaks its rule.
        """
        rules = self.parameter_rules()
        owner = type(self).__name__
        return {name: rules[name](value, name, owner) for name, value in self.get_params().items()}

    def params_to_json(self) -> dict[str, Any]:
        """The constructor arguments as plain JSON data (separate from :meth:`get_params`).

        Returns
        -------
        dict
        """
        return {name: _to_json(value) for name, value in self.get_params().items()}

    @classmethod
    def params_from_json(cls, data: dict[str, Any]) -> dict[str, Any]:
        """Constructor arguments from :meth:`params_to_json` data.

        Parameters
        ----------
        data : dict

        Returns
        -------
        dict
        """
        out = dict(data)
        if "terms" in out:
            out["terms"] = tuple(_term_from_json(v) for v in out["terms"])
        return out

    @classmethod
    def _bare(cls, input_unit: str, output_unit: str, n_operators: int | None = None) -> Self:
        """An unfitted instance with default settings and these units (and operator count)."""
        model = cls.__new__(cls)
        for p in inspect.signature(cls.__init__).parameters.values():
            if p.name != "self":
                setattr(model, p.name, p.default)
        settings: dict[str, Any] = {"input_unit": input_unit, "output_unit": output_unit}
        if n_operators is not None and "n_operators" in model.get_params():
            settings["n_operators"] = n_operators
        for name, value in settings.items():
            setattr(model, name, value)
        return model


def _same(a: object, b: object) -> bool:
    try:
        return bool(a == b) if not isinstance(a, np.ndarray) else False
    except (ValueError, TypeError):
        return False


def _to_json(value: object) -> Any:
    if isinstance(value, type):  # a core class: its registry name
        return getattr(value, "kind", value.__name__)
    if isinstance(value, Term):
        return {"kind": value.kind, "params": value.get_params()}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple | list):
        return [_to_json(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _term_from_json(value: object) -> str | Term:
    if isinstance(value, dict):
        return make_term(str(value.get("kind")), value.get("params") or {})
    if isinstance(value, str):
        return value
    msg = f"a term must be a kind name or {{'kind', 'params'}}, got {value!r}"
    raise ParameterError(msg)

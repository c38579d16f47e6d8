"""The settings of an estimator, as scikit-learn keeps them: the ``__init__`` arguments, stored under their own names.

Shared by :class:`cappe.estimate.Estimator` and :class:`cappe.identify.PolynomialModel`, so that
``type(est)(**est.get_params())`` is an unfitted copy of any estimator and no setting is left out by hand.
"""

from __future__ import annotations

import inspect
from typing import Any, Self

from cappe.exceptions import ModelError

__all__ = ["Settings"]

_VARIADIC = (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)


class Settings:
    """``get_params`` and ``set_params`` read from the signature of the class's ``__init__``.

    A subclass's ``__init__`` must store every argument unchanged under the argument's name (and nothing else);
    validation belongs in ``fit``.
    """

    @classmethod
    def _setting_names(cls) -> tuple[str, ...]:
        """The names of the ``__init__`` arguments, in signature order (no ``self``, no ``*args`` / ``**kwargs``)."""
        parameters = list(inspect.signature(cls.__init__).parameters.values())[1:]
        return tuple(p.name for p in parameters if p.kind not in _VARIADIC)

    def get_params(self) -> dict[str, Any]:
        """The settings given to ``__init__``, by name; ``type(self)(**self.get_params())`` is an unfitted copy.

        Returns
        -------
        dict
            ``{argument name: value}`` for every ``__init__`` argument, in signature order.
        """
        return {name: getattr(self, name) for name in self._setting_names()}

    def set_params(self, **params: Any) -> Self:
        """Change settings; they take effect at the next ``fit`` (learned values are not updated).

        Parameters
        ----------
        **params
            ``name=value`` for any of the ``__init__`` arguments.

        Returns
        -------
        self

        Raises
        ------
        ModelError
            A name is not an ``__init__`` argument of the estimator.
        """
        names = self._setting_names()
        unknown = sorted(set(params) - set(names))
        if unknown:
            msg = f"{type(self).__name__} has no setting(s) {unknown}; its settings are {list(names)}"
            raise ModelError(msg)
        for name, value in params.items():
            setattr(self, name, value)
        return self

"""Parameter names of scikit-learn-style estimators whose subclasses take ``**kwargs``.

scikit-learn's ``BaseEstimator.get_params`` reads the parameter names from the signature of the
class's own ``__init__`` and skips ``**kwargs``, so a subclass written as
``def __init__(self, n=3, **kw): super().__init__(**kw); self.n = n`` silently drops every
inherited parameter from ``get_params``, ``clone`` and ``repr``. :class:`InheritedParams`
collects the names along the method resolution order instead: the names of each ``__init__``,
continuing to the parent's while an ``__init__`` forwards ``**kwargs``.
"""

from __future__ import annotations

import inspect

__all__ = ["InheritedParams"]


class InheritedParams:
    """Mixin (before ``BaseEstimator`` in the bases) for estimators meant to be subclassed."""

    @classmethod
    def _get_param_names(cls) -> list[str]:
        names: set[str] = set()
        for klass in cls.__mro__:
            init = klass.__dict__.get("__init__")
            if init is None or init is object.__init__:
                continue
            params = list(inspect.signature(init).parameters.values())[1:]
            if any(p.kind is p.VAR_POSITIONAL for p in params):
                raise RuntimeError(f"{klass.__qualname__}.__init__ takes *args; scikit-learn-style "
                                   "estimators take keyword parameters only")
            names |= {p.name for p in params if p.kind is not p.VAR_KEYWORD}
            if not any(p.kind is p.VAR_KEYWORD for p in params):
                break
        return sorted(names)

"""Values that depend on a hand model alone, computed once per model object.

A HandModel is frozen and compared by identity, so a value derived from its arrays holds for as long as the object
lives: a dataset frame asks for the same model's joint frames, digit masks or regressor rows again and again (each
frame has a new shape, but the model it is shaped from is the source's one). The values are kept in a weak
dictionary (dropped with their model) and shared between callers, so arrays among them are made read-only.
"""

from __future__ import annotations

import functools
import threading
import weakref
from typing import Callable, TypeVar

import numpy as np

from darthand.model.hand_model import HandModel

T = TypeVar("T")

_VALUES: "weakref.WeakKeyDictionary[HandModel, dict]" = weakref.WeakKeyDictionary()
_LOCK = threading.Lock()


def per_model(fn: Callable[[HandModel], T]) -> Callable[[HandModel], T]:
    """Decorator: `fn(model)` worked out on a model's first call and returned again, the same object, on later
    calls with the same model. Array values (alone or in a tuple) come back read-only."""

    @functools.wraps(fn)
    def kept(model: HandModel) -> T:
        with _LOCK:
            values = _VALUES.setdefault(model, {})
            if fn in values:
                return values[fn]
        value = _read_only(fn(model))
        with _LOCK:
            return values.setdefault(fn, value)
    return kept


def _read_only(value):
    for a in value if isinstance(value, tuple) else (value,):
        if isinstance(a, np.ndarray):
            a.flags.writeable = False
    return value

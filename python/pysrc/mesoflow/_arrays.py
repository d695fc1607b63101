"""Arrays handed to the engine: real numbers only, C order."""

from typing import Any

import numpy as np


def real_array(value: Any, dtype: Any) -> np.ndarray:
    """``value`` as a C-ordered array of ``dtype``; raises ``TypeError`` for anything that is not
    an array of real numbers (complex, datetime, timedelta, object, text), which a cast would
    otherwise silently turn into something else (the real part, nanoseconds)."""
    a = np.asarray(value)
    if a.dtype.kind not in "biuf":
        raise TypeError(
            f"an array of {a.dtype} is not one of real numbers: complex, datetime, object and "
            "text arrays are refused, never converted"
        )
    return np.ascontiguousarray(a, dtype=dtype)

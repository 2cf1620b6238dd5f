"""IEEE single precision for generated float code: exact rounding and the C spelling.

Constants baked into ``--scalar float`` code are rounded once, from their exact value (a
rational, or the double the description gave), to the nearest float (ties to even), and
spelled with the fewest digits that read back as that float:

>>> from fractions import Fraction
>>> c_float(Fraction(1, 3)), c_float(0.1), c_float(1), c_float(Fraction(1, 2**30))
('0.33333334f', '0.1f', '1.0f', '9.313226e-10f')
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np


class FloatRangeError(ValueError):
    """A constant that float code cannot hold (beyond FLT_MAX, or nonzero below the normal
    range): the description needs double code (``generate`` reports it as bad input)."""


def nearest_float32(value) -> np.float32:
    """The float nearest to the exact ``value`` (int, Fraction or float), ties to even.

    >>> float(nearest_float32(Fraction(16777217)))   # 2^24 + 1: halfway, to the even 2^24
    16777216.0
    """
    exact = Fraction(value)
    if abs(exact) > FLT_MAX:
        raise FloatRangeError(f"constant {float(exact)!r} is outside the float range")
    guess = np.float32(float(exact))       # within one float ulp of the answer (two roundings)
    with np.errstate(over="ignore"):
        candidates = (np.nextafter(guess, np.float32(-np.inf)), guess, np.nextafter(guess, np.float32(np.inf)))

    def key(c):
        odd = int(np.frombuffer(c.tobytes(), dtype=np.uint32)[0]) & 1
        return abs(Fraction(float(c)) - exact), odd
    return min((c for c in candidates if np.isfinite(c)), key=key)


FLT_MAX = Fraction(float(np.finfo(np.float32).max))
FLT_MIN = Fraction(float(np.finfo(np.float32).tiny))     # the smallest normal float, 1.2e-38


def c_float(value) -> str:
    """The C literal (``f`` suffix) of the float nearest to ``value``. A nonzero constant
    below float's normal range is refused, as one beyond its largest value is: it would be
    printed as 0 (or a denormal), and a guard such as 1 / max(x, 1e-150) would become 1/0
    (the closed-form IK's tolerances are per scalar type for that reason:
    kindyngen/ik/lwr_common.py, TOLERANCES).

    >>> c_float(1e-30)
    '1e-30f'
    >>> c_float(1e-150)      # doctest: +IGNORE_EXCEPTION_DETAIL
    Traceback (most recent call last):
    ...
    FloatRangeError: constant 1e-150 is below float's normal range (1.2e-38): it would round to 0.0
    """
    if value != 0 and abs(Fraction(value)) < FLT_MIN:
        raise FloatRangeError(f"constant {float(value)!r} is below float's normal range (1.2e-38): "
                         f"it would round to {float(nearest_float32(value))!r}")
    text = str(nearest_float32(value))      # numpy: the shortest digits that round-trip
    if "." not in text and "e" not in text:
        text += ".0"
    return text + "f"

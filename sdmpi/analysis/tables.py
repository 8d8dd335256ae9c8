"""How reduced tables write their values: one spelling for every CSV the reducer writes."""

import math

import numpy as np


def csv_value(x) -> str:
    """A table cell: strings as they are, integers plainly, floats by repr (round-trip
    exact), NaN as "nan"."""
    if isinstance(x, str):
        return x
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    return "nan" if math.isnan(x) else repr(float(x))

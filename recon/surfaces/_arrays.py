"""Array helpers shared by the surface methods and the judge."""

from __future__ import annotations

import numpy as np


def unique_sorted(values: np.ndarray) -> np.ndarray:
    """The distinct values of an integer array, ascending: ``np.unique(values)`` by sorting.

    NumPy 2.3 and later find ``np.unique``'s values through a hash table when no indices or
    counts are asked for; on hundreds of thousands of grid keys or face indices that is many
    times slower than sorting a copy and keeping each run's first value, which gives the same
    array.

    Parameters
    ----------
    values : array_like of int
        Any shape (flattened).

    Returns
    -------
    (u,) ndarray of the same integer dtype
    """
    ordered = np.sort(np.asarray(values).ravel())
    if not np.issubdtype(ordered.dtype, np.integer):
        raise TypeError(f"unique_sorted: integer values only, got {ordered.dtype}")
    keep = np.empty(len(ordered), dtype=bool)
    keep[:1] = True
    np.not_equal(ordered[1:], ordered[:-1], out=keep[1:])
    return ordered[keep]

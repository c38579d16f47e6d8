"""The one place where seeds become random generators."""

from __future__ import annotations

import numpy as np

__all__ = ["RandomLike", "as_generator"]

RandomLike = int | np.random.Generator | None


def as_generator(rng: RandomLike) -> np.random.Generator:
    """Return a numpy Generator for ``rng``.

    Parameters
    ----------
    rng : int | numpy.random.Generator | None
        A seed (0 is a valid seed), an existing generator (returned as is) or None for fresh entropy.

    Examples
    --------
    >>> int(as_generator(0).integers(10)) == int(as_generator(0).integers(10))
    True
    """
    if rng is None:
        return np.random.default_rng()
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        return np.random.default_rng(int(rng))
    msg = f"rng must be an int seed, a numpy Generator or None; got {type(rng).__name__}"
    raise TypeError(msg)

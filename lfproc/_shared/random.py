"""Random generators: every stochastic function normalises its ``random_state`` here."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["check_random_state"]


def check_random_state(random_state: Any = None) -> np.random.Generator:
    """Return a :class:`numpy.random.Generator` from a seed, a Generator or ``None``.

    Every stochastic function of lfproc takes ``random_state`` and passes it here,
    so a given integer seed always gives the same result.
    """
    if random_state is None or isinstance(random_state, (int, np.integer)):
        if random_state is not None and int(random_state) < 0:
            raise InputError(f"seed: expected a non-negative integer, got {random_state}")
        return np.random.default_rng(random_state)
    if isinstance(random_state, np.random.Generator):
        return random_state
    raise InputError(
        f"random_state: expected None, an int seed or a numpy Generator, got {type(random_state).__name__}"
    )

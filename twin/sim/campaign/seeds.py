"""The random generator of each unit of work of a campaign.

Determinism: every random draw comes from ``numpy.random.SeedSequence([seed, kind, index...])``,
so a unit of work gives the same arrays whichever process, executor or order runs it. The kinds
are numbered here (:data:`KIND_WORLD`, ... :data:`KIND_ORIGIN`).
"""

from __future__ import annotations

import numpy as np

KIND_WORLD, KIND_PHASE1, KIND_PHASE2, KIND_DIAL, KIND_ORIGIN = range(5)


def rng_for(seed: int, kind: int, *index: int) -> np.random.Generator:
    """The generator of one unit of work: a pure function of the seed, the kind and the index."""
    return np.random.default_rng(np.random.SeedSequence([seed, kind, *index]))

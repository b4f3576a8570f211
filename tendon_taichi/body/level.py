"""Resolution levels: how a scene's sizes shrink from level 1 (the scene as
written) to level N (``docs/scenes.md``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LevelScale:
    """How resolution ``level`` (1, 2, ...) scales the scene's sizes: each level
    halves the largest triangle area and divides the fiber spacing (a length) by
    sqrt(2). ``length`` and ``area`` are the divisors of a level-1 length and area."""

    level: int

    @property
    def length(self) -> float:
        """sqrt(2) ** (level - 1): a level-1 length over this level's."""
        return np.sqrt(2.0) ** (self.level - 1)

    @property
    def area(self) -> int:
        """2 ** (level - 1): a level-1 area over this level's."""
        return 2 ** (self.level - 1)


def level_scale(level: int) -> LevelScale:
    """The one place a level's sizes are derived from level 1's (:class:`LevelScale`)."""
    return LevelScale(int(level))

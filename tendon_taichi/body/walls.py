"""The walls protocol: what route clearance asks of a body's boundary, in any
dimension. The polygon set of a 2D body (:class:`~.geometry.PolygonWalls`)
implements it today; a triangle surface will for a 3D body. Points are
``(q, dim)`` arrays in metres, in the rest configuration."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Walls(Protocol):
    """A body's boundary (its outline and holes in 2D, its surface in 3D)."""

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (q,) of points (q, dim) from the nearest wall, m:
        positive inside the body, negative outside."""

    def distance_gradient(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distances (q,) and their gradients (q, dim): unit vectors away from
        the nearest wall, into the body."""

    def inside(self, points: np.ndarray) -> np.ndarray:
        """bool (q,): whether each point (q, dim) lies in the body (walls included)."""

    def polyline_distance(self, points: np.ndarray) -> float:
        """The least distance (m) of a polyline (k, dim) from the walls, its segments
        included; negative when it leaves the body."""

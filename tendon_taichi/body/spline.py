"""Clamped uniform B-splines in the plane: the curves tendon routes are made of.

A spline with ``m`` control points has degree ``k = min(3, m - 1)`` and the
knots ``0 (k+1 times), uniform inner knots, 1 (k+1 times)``, so it starts at
its first control point and ends at its last. :func:`basis` samples it (the
samples are linear in the control points); :func:`bezier_pieces` gives it
exactly as cubic Bezier segments, for drawings (SVG paths).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.interpolate import BSpline


def knots(n_control: int) -> tuple[np.ndarray, int]:
    """The clamped uniform knot vector of a spline with ``n_control`` control points
    (at least 2), and its degree."""
    k = min(3, n_control - 1)
    inner = np.linspace(0.0, 1.0, n_control - k + 1)[1:-1]
    return np.r_[np.zeros(k + 1), inner, np.ones(k + 1)], k


@lru_cache(maxsize=256)
def basis(n_samples: int, n_control: int) -> np.ndarray:
    """(n_samples, n_control): the spline's basis functions at ``n_samples`` parameters
    evenly spread over [0, 1] (read-only)."""
    t, k = knots(n_control)
    B = BSpline.design_matrix(np.linspace(0.0, 1.0, n_samples), t, k).toarray()
    B.setflags(write=False)
    return B


#: cubic Bernstein polynomials at u = 0, 1/3, 2/3, 1 (rows) - inverted, they turn
#: four points of a cubic piece into its Bezier control points
_BERNSTEIN = np.array([[(1 - u) ** 3, 3 * u * (1 - u) ** 2, 3 * u * u * (1 - u), u ** 3]
                       for u in (0.0, 1 / 3, 2 / 3, 1.0)])


def bezier_pieces(control: np.ndarray) -> np.ndarray:
    """The spline of ``control`` (m, 2) as cubic Bezier segments (s, 4, 2), one per
    knot interval, exactly (a piece of degree < 3 is a cubic too)."""
    control = np.asarray(control, dtype=float)
    t, k = knots(len(control))
    spline = BSpline(t, control, k)
    breaks = np.unique(t)
    out = []
    for a, b in zip(breaks[:-1], breaks[1:]):
        u = a + (b - a) * np.array([0.0, 1 / 3, 2 / 3, 1.0])
        out.append(np.linalg.solve(_BERNSTEIN, spline(u)))
    return np.array(out)

"""Smooth tendon routes off the lattice (``docs/method.md``, routes).

A route is a clamped cubic B-spline in the rest body: its first control point
is the anchor, its last the pull end, the others shape it. Its waypoints are
the curve sampled at fixed parameters, so they are linear in the control
points (``waypoints = B @ control``, :func:`basis`) and a gradient w.r.t. the
waypoints becomes one w.r.t. the control points by ``B^T``. How many control
points and waypoints a route has depends on its length relative to the body
size L only, never on the mesh: a route means the same at every resolution.

:func:`fit_route` turns an extracted chain of lattice fibers into a route (a
least-squares fit with the ends held, smoothed so that a 45-degree zig-zag
becomes the line it approximates); :func:`join_routes` and
:func:`extend_route` make new routes from old. Keeping clear of the walls is
:mod:`.clearance`'s.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..body.spline import basis
from .protocol import Tendon

#: waypoints per unit of route length L (one every 1.5 % of L) ...
SAMPLES_PER_L = 1.0 / 0.015
#: ... at least and at most
MIN_SAMPLES, MAX_SAMPLES = 8, 80
#: control points: 4, one more per this fraction of L of length, at most MAX_CONTROL
CONTROL_PER_L = 0.12
MAX_CONTROL = 7
#: second-difference smoothing of the fit, relative to the data term
FIT_SMOOTHING = 0.05


def polyline_length(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def sample_count(length: float, size: float) -> int:
    """Waypoints of a route ``length`` m long in a body of size ``size`` m."""
    return int(np.clip(np.ceil(length / size * SAMPLES_PER_L) + 1, MIN_SAMPLES, MAX_SAMPLES))


def control_count(length: float, size: float) -> int:
    """Control points of a route ``length`` m long in a body of size ``size`` m."""
    return int(np.clip(4 + np.floor(length / size / CONTROL_PER_L), 4, MAX_CONTROL))


@dataclass
class Route:
    """A smooth route: ``control`` (m, 2) rest coordinates, m (anchor first, pull end
    last), sampled at ``samples`` waypoints; ``tension`` and ``tension_std`` (N) of the
    strand it came from, and ``source``, the extractor (or 'join') that made it;
    ``kept_clearance`` (m): None where the route keeps the asked clearance from the
    walls, else the smaller one it keeps (the body is too narrow for the asked one
    there, :func:`~.clearance.clear_route`). A route that leaves the body
    (``docs/method.md``, exits) has its pull end on the segment ``exit`` (2, 2) of
    the body's exit set and ``core``, the route before its run to there
    (:func:`~.exits.exit_route`); joins and extensions start from the core."""

    control: np.ndarray
    samples: int
    tension: float = 0.0
    tension_std: float = 0.0
    source: str = ""
    contraction: float | None = None
    kept_clearance: float | None = None
    exit: np.ndarray | None = None
    core: "Route | None" = None

    @property
    def exits(self) -> bool:
        """Whether the route leaves the body at its pull end."""
        return self.exit is not None

    @property
    def basis(self) -> np.ndarray:
        return basis(self.samples, len(self.control))

    @property
    def waypoints(self) -> np.ndarray:
        """The waypoints (samples, 2), m."""
        return self.basis @ self.control

    @property
    def length(self) -> float:
        return polyline_length(self.waypoints)

    def with_control(self, control: np.ndarray) -> "Route":
        return replace(self, control=np.array(control, dtype=float).reshape(-1, 2))

    def reversed(self) -> "Route":
        """The same curve pulled at the other end (a route that leaves the body no longer does)."""
        return replace(self.with_control(self.control[::-1]), exit=None, core=None)

    def inner(self) -> "Route":
        """The route without its run out of the body: its core, or itself."""
        return self if self.core is None else self.core

    def tendon(self) -> Tendon:
        """The route as a tendon of the realizable robot (waypoints off the lattice)."""
        return Tendon(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), self.waypoints, self.tension,
                      self.tension_std, contraction=self.contraction, control=self.control.copy(),
                      exit=None if self.exit is None else self.control[-1].copy())


def resample(points: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points evenly spaced by arc length along a polyline (k, 2), and their
    arc-length parameters in [0, 1]."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    u = np.linspace(0.0, 1.0, n)
    if s[-1] <= 0:
        return np.repeat(points[:1], n, axis=0), u
    target = u * s[-1]
    return np.stack([np.interp(target, s, points[:, d]) for d in (0, 1)], axis=1), u


def smooth_fit(B: np.ndarray, target: np.ndarray, smoothing: float = FIT_SMOOTHING,
               ends: np.ndarray | None = None, weights: np.ndarray | None = None) -> np.ndarray:
    """Control points (m, 2) with ``B @ control`` nearest ``target`` (k, 2) in the
    (``weights`` (k,)-weighted) least squares, plus ``smoothing`` times the mean
    squared second difference of the control points (so a fit does not wiggle);
    ``ends`` (2, 2), where given, fixes the first and the last control point."""
    n, m = B.shape
    if m == 2 and ends is not None:
        return np.array(ends, dtype=float)
    W = np.ones(n) if weights is None else np.asarray(weights, dtype=float)
    D = np.diff(np.eye(m), 2, axis=0)
    A = B.T @ (W[:, None] * B) / W.sum() + smoothing * D.T @ D / max(len(D), 1)
    rhs = B.T @ (W[:, None] * target) / W.sum()
    if ends is None:
        return np.linalg.solve(A, rhs)
    inner, fixed = np.arange(1, m - 1), np.array([0, m - 1])
    c = np.zeros((m, 2))
    c[fixed] = ends
    c[inner] = np.linalg.solve(A[np.ix_(inner, inner)], rhs[inner] - A[np.ix_(inner, fixed)] @ c[fixed])
    return c


def fit_control(points: np.ndarray, n_control: int, smoothing: float = FIT_SMOOTHING) -> np.ndarray:
    """Control points (n_control, 2) of the clamped B-spline that fits a polyline
    (k, 2) by arc length, with its ends on the polyline's ends (:func:`smooth_fit`)."""
    n = max(4 * n_control, 40)
    target, _ = resample(np.asarray(points, dtype=float), n)
    return smooth_fit(basis(n, n_control), target, smoothing, ends=target[[0, -1]])


def fit_route(points: np.ndarray, size: float, tension: float = 0.0, tension_std: float = 0.0,
              source: str = "") -> Route:
    """A route through a polyline (k, 2) of rest waypoints (an extracted tendon)."""
    points = np.asarray(points, dtype=float)
    length = polyline_length(points)
    return Route(fit_control(points, control_count(length, size)), sample_count(length, size),
                 tension, tension_std, source)


def extend_route(route: Route, end: int, distance: float, size: float) -> Route:
    """The route carried on straight along its tangent at its anchor (``end`` 0) or
    pull end (``end`` 1) by ``distance`` (m): a smooth fit of its waypoints and the
    straight piece (control points for the new length), its tension and source kept."""
    pts = route.waypoints if end == 1 else route.waypoints[::-1]
    tangent = pts[-1] - pts[-2]
    tangent = tangent / max(float(np.linalg.norm(tangent)), 1e-300)
    step = np.linspace(0.0, distance, max(2, int(np.ceil(distance * SAMPLES_PER_L / size)) + 1))[1:]
    pts = np.vstack([pts, pts[-1] + step[:, None] * tangent])
    return fit_route(pts if end == 1 else pts[::-1], size, route.tension, route.tension_std, route.source)


def join_routes(a: Route, b: Route, size: float) -> Route:
    """One route along ``a`` (anchor first), across the gap to ``b``'s anchor, and
    along ``b``: a smooth fit of the three, never a lattice path; its tension is
    the length-weighted mean of theirs."""
    pts = np.concatenate([a.waypoints, b.waypoints])
    la, lb = a.length, b.length
    w = la / max(la + lb, 1e-300)
    tension = w * a.tension + (1 - w) * b.tension
    std = float(np.sqrt(w * a.tension_std ** 2 + (1 - w) * b.tension_std ** 2))
    return fit_route(pts, size, tension, std, "join")

"""Routes that keep clear of the walls: a constrained fit (``docs/method.md``, routes).

A route's polyline - its waypoints and the segments between them, looked at in
points ``q_j = A_j c`` linear in the control points ``c`` (m, dim) - must keep
the clearance ``h`` from the walls. Where it does not, :func:`clear_route` moves
it least, by solving

    minimize    f(c) = sum_j |A_j c - p_j|^2 / (n h^2) + s |D c|^2 / (len(D) h^2)
    subject to  d(A_j c) >= h          for every j

by SLSQP, the walls' distance gradient giving the constraint's Jacobian
(``d d(q_j) / d c_i = A_ji grad d(q_j)``); ``p_j`` are the route's points before
the move, ``D`` the second differences of the control points (a little
smoothing, ``s``, so a moved route does not wiggle). Where no route near it can
keep ``h`` - the body is narrower than ``2 h`` there - it keeps the largest
clearance ``t`` it can:

    maximize t - eps f(c)   subject to   d(A_j c) >= t,  t <= h

and then the least change that keeps that ``t``; such a route is *flagged*: its
``kept_clearance`` says what it keeps, and it is never left out.
An end that runs head-on into a wall is first cut back along the route to where
it keeps ``h`` (the tendon then ends inside the body). A route that leaves the
body (:mod:`.exits`) keeps its exit where it is and sees the walls lifted within
the exit's zone (:func:`route_walls`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.optimize as so

from ..body.exits import ExitWalls
from ..body.walls import Walls
from .routes import Route, fit_control, resample

#: smoothing s of the constrained fit, relative to its data term
CLEAR_SMOOTHING = 0.005
#: weight eps of the change while the largest clearance is sought
CHANGE_WEIGHT = 1e-3
#: SLSQP iterations of one constrained fit, and its tolerance on f
CLEAR_ITERATIONS, FTOL = 100, 1e-9
#: how far a fit may move a control point, in units of the clearance plus what the route lacks of it
REACH = 2.0
#: points per segment between waypoints on the finest look for points that come too close (a
#: wall's corner can come closer between the waypoints held: its closest point is held then,
#: and the fit solved again, at most LOOKS times)
MAX_PARTS = 256
LOOKS = 6
#: a route keeps a clearance within this fraction of it ...
CLEAR_TOL = 1e-6
#: ... and the fit asks for this fraction more (SLSQP ends its constraints' values about this close)
MARGIN = 2e-3
#: a route moved, joined or carried on may keep this fraction less clearance than it came with
KEPT_TOL = 1e-3


def along_segments(B: np.ndarray, parts: int) -> np.ndarray:
    """Rows of B ((k, m): waypoints from control points) for ``parts`` evenly spread
    points along every segment between consecutive waypoints, the last waypoint
    included: ((k - 1) parts + 1, m), the polyline's points linear in the control points."""
    t = np.arange(parts) / parts
    rows = (1.0 - t)[None, :, None] * B[:-1, None, :] + t[None, :, None] * B[1:, None, :]
    return np.vstack([rows.reshape(-1, B.shape[1]), B[-1:]])


def route_walls(route: Route, walls: Walls, clearance: float) -> Walls:
    """The walls as ``route`` is held to them: as they are, or for a route that leaves
    the body, lifted within its exit's zone (:class:`~tendon_taichi.body.exits.ExitWalls`)."""
    return walls if route.exit is None else ExitWalls(walls, route.control[-1], clearance)


def held_clearance(route: Route, clearance: float) -> float:
    """The clearance (m) ``route`` is held to: the asked ``clearance``, or less
    where it is flagged (it keeps less, :func:`clear_route`)."""
    return clearance if route.kept_clearance is None else min(clearance, route.kept_clearance)


def keeps_as_much(route: Route, held: float, clearance: float) -> bool:
    """Whether ``route`` is held to at least ``held`` (m) of the asked ``clearance``
    (within KEPT_TOL): what a route made from others must keep."""
    return held_clearance(route, clearance) >= held * (1.0 - KEPT_TOL)


def keep_clear(route: Route, walls: Walls, clearance: float) -> Route | None:
    """The route made to keep ``clearance`` (m) along its whole polyline
    (:func:`clear_route`), or None where it cannot (the body is too narrow there)."""
    out = clear_route(route, walls, clearance)
    return out if out.kept_clearance is None else None


def clear_route(route: Route, walls: Walls, clearance: float) -> Route:
    """The route moved least so that its polyline keeps ``clearance`` (m) from
    ``walls`` (module docstring); where that cannot be done, the route that keeps
    the largest clearance it can, flagged with it (``kept_clearance``, m). A route
    that keeps the clearance already comes back as it is (unflagged); one that
    leaves the body keeps its exit."""
    walls = route_walls(route, walls, clearance)
    target = clearance * (1.0 - CLEAR_TOL)
    if walls.polyline_distance(route.waypoints) >= target:
        return route if route.kept_clearance is None else replace(route, kept_clearance=None)
    pts = route.waypoints
    if walls.distance(pts[[0, -1]]).min() < clearance:
        route = route.with_control(fit_control(_trim_ends(pts, walls, clearance * (1.0 + 1e-3)),
                                               len(route.control)))
    fit = _Fit(route, walls, clearance)
    control = fit.solve(route.control, clearance)
    if control is not None:
        return replace(route.with_control(control), kept_clearance=None)
    control, kept = fit.widest(route.control)
    if kept > 0:  # the least change that keeps (nearly) that much
        closer = fit.solve(control, kept * (1.0 - KEPT_TOL))
        if closer is not None:
            control, kept = closer, walls.polyline_distance(route.basis @ closer)
    return replace(route.with_control(control), kept_clearance=None if kept >= target else float(kept))


class _Fit:
    """The constrained fit of :func:`clear_route` for one route, in units of the
    clearance ``h`` (m): its variables are the control points over h, ``u``
    ((m dim,)), held within ``REACH (h + lack)`` of where they were (``lack``: how
    much the closest point lacks of h), so a fit moves the route near where it
    ran, never round to another way. The change is measured at the points
    ``A_fit`` (the waypoints, where they were: ``p``), the clearance held at
    ``A_keep`` (those, and each point of the polyline a finer look found too close)."""

    def __init__(self, route: Route, walls: Walls, h: float):
        self.route, self.walls, self.h = route, walls, h
        self.m = len(route.control)
        D = np.diff(np.eye(self.m), 2, axis=0)
        self.DtD = D.T @ D / max(len(D), 1)
        self.A_fit = route.basis
        self.p = self.A_fit @ route.control / h
        self.A_keep = self.A_fit
        lack = max(0.0, h - float(walls.distance(self.p * h).min()))
        reach = REACH * (h + lack) / h
        self.bounds = [(v - reach, v + reach) for v in route.control.ravel() / h]
        if route.exit is not None:  # the exit stays where it is
            dim = route.control.shape[1]
            self.bounds[-dim:] = [(v, v) for v in route.control[-1] / h]

    def change(self, u: np.ndarray) -> tuple[float, np.ndarray]:
        """f and its gradient at u."""
        c = u.reshape(self.m, -1)
        r = self.A_fit @ c - self.p
        n = len(self.A_fit)
        f = (r * r).sum() / n + CLEAR_SMOOTHING * (c * (self.DtD @ c)).sum()
        g = 2.0 * (self.A_fit.T @ r) / n + 2.0 * CLEAR_SMOOTHING * (self.DtD @ c)
        return float(f), g.ravel()

    def room(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The distances (q,) of the points held at u, over h, and their Jacobian (q, m dim)."""
        d, g = self.walls.distance_gradient(self.A_keep @ u.reshape(self.m, -1) * self.h)
        return d / self.h, (self.A_keep[:, :, None] * g[:, None, :]).reshape(len(d), -1)

    def control(self, u: np.ndarray) -> np.ndarray:
        """The control points (m, dim) at u, m."""
        return u.reshape(self.m, -1) * self.h

    def look_closer(self, u: np.ndarray, clearance: float) -> bool:
        """Whether the whole polyline at u keeps ``clearance`` (m); where it does not,
        the closest point of each stretch that comes closer (on the first look fine
        enough to find one) is held from now on."""
        control = self.control(u)
        if self.walls.polyline_distance(self.route.basis @ control) >= clearance * (1.0 - CLEAR_TOL):
            return True
        parts = 2
        while parts <= MAX_PARTS:
            A = along_segments(self.route.basis, parts)
            d = self.walls.distance(A @ control)
            short = np.flatnonzero(d < clearance * (1.0 - 0.5 * CLEAR_TOL))
            if len(short):
                runs = np.split(short, np.flatnonzero(np.diff(short) > 1) + 1)
                self.A_keep = np.vstack([self.A_keep, A[[r[np.argmin(d[r])] for r in runs]]])
                return False
            parts *= 2
        return False

    def solve(self, control: np.ndarray, clearance: float) -> np.ndarray | None:
        """The control points (m, dim) of the least change (from the route's own
        points) that keeps ``clearance`` (m), started at ``control``; None where
        SLSQP finds none within reach."""
        u = control.ravel() / self.h
        held = clearance / self.h
        for _ in range(LOOKS):
            room = _Cached(self.room)
            cons = {"type": "ineq", "fun": lambda u: room(u)[0] - held * (1.0 + MARGIN), "jac": lambda u: room(u)[1]}
            u = so.minimize(self.change, u, jac=True, method="SLSQP", bounds=self.bounds, constraints=[cons],
                            options={"maxiter": CLEAR_ITERATIONS, "ftol": FTOL}).x
            if room(u)[0].min() < held * (1.0 - MARGIN):
                return None  # not even the points held keep it
            if self.look_closer(u, clearance):
                return self.control(u)
        return None

    def widest(self, control: np.ndarray) -> tuple[np.ndarray, float]:
        """The control points (m, dim) within reach of ``control`` that keep the
        largest clearance t <= h, changed little, and that t (m)."""
        n = control.size
        room = _Cached(self.room)

        def objective(y):
            f, g = self.change(y[:n])
            return -y[n] + CHANGE_WEIGHT * f, np.r_[CHANGE_WEIGHT * g, -1.0]

        cons = {"type": "ineq", "fun": lambda y: room(y[:n])[0] - y[n] * (1.0 + MARGIN),
                "jac": lambda y: np.hstack([room(y[:n])[1], np.full((len(room(y[:n])[1]), 1), -1.0 - MARGIN)])}
        best_u, best_t = control.ravel() / self.h, -np.inf
        y = np.r_[best_u, room(best_u)[0].min()]
        for _ in range(LOOKS):
            y = so.minimize(objective, y, jac=True, method="SLSQP", bounds=self.bounds + [(None, 1.0)],
                            constraints=[cons], options={"maxiter": CLEAR_ITERATIONS, "ftol": FTOL}).x
            t = self.walls.polyline_distance(self.route.basis @ self.control(y[:n]))
            if t > best_t:
                best_u, best_t = y[:n].copy(), t
            if self.look_closer(y[:n], y[n] * self.h):
                break
            room = _Cached(self.room)
        return self.control(best_u), float(best_t)


class _Cached:
    """A function of one array remembered at its last argument (SLSQP asks for a
    constraint's values and Jacobian at the same point in turn)."""

    def __init__(self, fn):
        self.fn, self.at, self.value = fn, None, None

    def __call__(self, x: np.ndarray):
        if self.at is None or not np.array_equal(self.at, x):
            self.at, self.value = np.array(x), self.fn(x)
        return self.value


def _trim_ends(points: np.ndarray, walls: Walls, clearance: float) -> np.ndarray:
    """A polyline (k, dim) with each end that runs head-on into a wall closer than
    ``clearance`` cut back (along the polyline, densely resampled) to where it
    keeps that clearance; an end that runs along a wall is kept (the fit moves it
    off). Head-on: going back along the route from the end, the distance from
    the walls grows at least as fast as along a 45-degree line."""
    dense, _ = resample(points, max(200, 4 * len(points)))
    d = walls.distance(dense)
    step = float(np.linalg.norm(dense[1] - dense[0]))
    lo, hi = 0, len(dense) - 1
    for order in (1, -1):
        dd = d[::order]
        if dd[0] >= clearance or step <= 0:
            continue
        k = min(8, len(dd) - 1)
        if (dd[k] - dd[0]) / (k * step) < np.sin(np.pi / 4):  # along the wall
            continue
        clear = np.flatnonzero(dd >= clearance)
        if len(clear):
            if order > 0:
                lo = int(clear[0])
            else:
                hi = len(dense) - 1 - int(clear[0])
    return dense[lo:hi + 1] if hi - lo >= 2 else points

"""Route optimization (``docs/method.md``, routes): the control points of every
route - anchor and pull end included - and each pose's tendon contractions,
moved together to minimize

    O = O_pose + O_reg                                   (the realizable soft IK, as built)
      + w_fric sum_t (1 - exp(-mu Theta_t))              (the pull the routes lose to their bends)
      + w_bend sum_j max(0, |theta_j| - theta_max)^2     (bends sharper than a channel takes)
      + w_bend sum_t max(0, Theta_t - Theta_max)^2       (routes that turn back on themselves)

subject to ``d_i >= c`` (every waypoint keeps the clearance from the walls; a
route that leaves the body, but within its exit's zone, :mod:`.exits`, and with
its exit held on its exit segment).
``Theta_t`` is route t's rest turning (smoothed where it is straight),
``theta_j`` the turn at one of its waypoints, ``d_i`` a waypoint's distance
from the walls and ``c`` the clearance. The friction price ``w_fric`` is
PRICE_PER_BUDGET times the budget squared: losing an eighth of a tendon's
pull weighs as much as a pose error of the whole budget. The terms on the
routes' shape alone (all but the pose and the regularizer) are
:func:`shape_cost`, which consolidation ranks layouts by too. The gradient
w.r.t. the contractions is the soft IK's; w.r.t. a waypoint's rest position it
is ``-lambda^T dR/dX`` from the same adjoint solve
(:func:`~tendon_taichi.physics.waypoints.rest_point_gradient`), and the
waypoints are linear in the control points (:mod:`.routes`). Every evaluation
embeds the waypoints in the rest mesh anew and solves each pose's as-built
equilibrium (capstan friction included), warm started from the last one; the
adjoint solve follows only where SLSQP asks for the gradient (the point its line
search accepts, :meth:`RouteObjective.gradient`), not at the trials it rejects. The
contractions are bounded by ``STROKE`` x max_contraction: a route shaped to need
the whole stroke on one mesh has none left on a finer one.

The clearance is a constraint, not a penalty: routes that do best run along
a wall, and a stiff penalty there made a quasi-Newton method step into it
and back out every other iteration (L-BFGS-B: 3696 evaluations in 1845
iterations on t_shape at level 2). SLSQP (sequential quadratic programming)
keeps the waypoints' distances as linearized constraints in each step
(:meth:`RouteObjective.clearance`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize as so

from ..body.problem import Problem
from ..errors import ConvergenceError
from ..objective.settings import OptimizeSettings
from ..optimizer.soft_ik import SoftIK
from ..physics.capstan import perp
from ..physics.waypoints import rest_point_gradient
from ..probes import probe
from .clearance import CLEAR_TOL, held_clearance, route_walls
from .context import Context
from .realizable import tendon_cables
from .routes import Route, polyline_length

#: the weight of the friction cost, in units of the budget (a fraction of L) squared ...
PRICE_PER_BUDGET = 8.0
#: ... and with the default budget, 0.5 % of L
FRICTION_PRICE = PRICE_PER_BUDGET * 0.005 ** 2
#: the sharpest turn at one waypoint (rad; waypoints are 1.5 % of L apart: a bend
#: radius of about 4 % of L) and the weight of the penalty on sharper ones
MAX_BEND = 0.35
BEND_WEIGHT = 1.0e-2
#: the most a route turns in all (rad, a quarter turn) before the same penalty
MAX_TURNING = np.pi / 2
#: smoothing of |theta| in the friction cost (rad): sqrt(theta^2 + d^2) - d
TURN_SMOOTHING = 1.0e-3
#: a route shorter than this (x L) has shrunk to a point (a trial step that put its control
#: points on one corner of their bounds): a tendon of no length, whose robot is not solved
COLLAPSED = 1e-9
#: route optimization keeps each contraction within this fraction of the scene's max_contraction:
#: routes shaped to need the whole stroke on one mesh have none left on a finer one (or on the bench)
STROKE = 0.9
#: SLSQP iterations of one route optimization: on the route optimizations of `design t_shape` and
#: `design finger_updown` at level 2, 40 end lower than L-BFGS-B's 60 did with the penalty (median
#: objective 0.97x and 0.93x) with 53-64 % of its evaluations (benchmarks/routes_side_by_side.py);
#: 30 ended about where it did (median 1.00x) with 40-47 %
ITERATIONS = 40


def turns(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The signed turns theta_j (k-2,) at the interior points of a polyline (k, 2),
    rad, and their gradients w.r.t. the segment before and after each, (k-2, 2) each."""
    d = np.diff(points, axis=0)
    a, b = d[:-1], d[1:]
    theta = np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], (a * b).sum(axis=1))
    ga = -perp(a) / np.maximum((a * a).sum(axis=1), 1e-300)[:, None]
    gb = perp(b) / np.maximum((b * b).sum(axis=1), 1e-300)[:, None]
    return theta, ga, gb


def _to_points(coef: np.ndarray, ga: np.ndarray, gb: np.ndarray, n: int) -> np.ndarray:
    """The gradient (n, 2) w.r.t. the points of sum_j f(theta_j), coef_j = f'(theta_j)."""
    g = np.zeros((n, 2))
    ga, gb = coef[:, None] * ga, coef[:, None] * gb
    # segment a_j = p[j+1] - p[j], b_j = p[j+2] - p[j+1]
    g[:-2] -= ga
    g[1:-1] += ga - gb
    g[2:] += gb
    return g


def turning(points: np.ndarray, delta: float = TURN_SMOOTHING) -> tuple[float, np.ndarray]:
    """Smoothed total turning sum_j (sqrt(theta_j^2 + delta^2) - delta) of a polyline
    (k, 2), rad, and its gradient (k, 2)."""
    if len(points) < 3:
        return 0.0, np.zeros_like(points)
    theta, ga, gb = turns(points)
    root = np.sqrt(theta * theta + delta * delta)
    return float((root - delta).sum()), _to_points(theta / root, ga, gb, len(points))


def sharp_bends(points: np.ndarray, limit: float = MAX_BEND) -> tuple[float, np.ndarray]:
    """sum_j max(0, |theta_j| - limit)^2 over the interior points of a polyline (k, 2),
    and its gradient (k, 2)."""
    if len(points) < 3:
        return 0.0, np.zeros_like(points)
    theta, ga, gb = turns(points)
    over = np.maximum(np.abs(theta) - limit, 0.0)
    return float((over * over).sum()), _to_points(2.0 * over * np.sign(theta), ga, gb, len(points))


def shape_cost(points: list[np.ndarray], rs: "RouteSettings") -> tuple[float, list[np.ndarray]]:
    """The terms of O on the routes' shape (module docstring: the friction price,
    sharp bends, turning back) for each route's waypoints (k, 2), and their
    gradients per route."""
    mu, wf, wb = rs.friction, rs.friction_price, rs.bend_weight
    total, grads = 0.0, []
    for p in points:
        sharp, g = sharp_bends(p)
        theta, gt = turning(p)
        over = max(theta - MAX_TURNING, 0.0)
        total += wb * (sharp + over * over)
        g = wb * (g + 2.0 * over * gt)
        if mu > 0.0 and wf > 0.0:
            keep = np.exp(-mu * theta)
            total += wf * (1.0 - keep)
            g = g + wf * mu * keep * gt
        grads.append(g)
    return total, grads


@dataclass
class RouteSettings:
    """``friction`` mu, ``clearance`` (m), ``friction_price`` and ``bend_weight``
    (module docstring), ``iterations``: the most SLSQP iterations of one
    optimization."""

    friction: float
    clearance: float
    friction_price: float = FRICTION_PRICE
    bend_weight: float = BEND_WEIGHT
    iterations: int = ITERATIONS


class RouteObjective:
    """O over ``z = [control points / L of every route, stacked; ratios (P, T)]``
    and its gradient (module docstring)."""

    def __init__(self, problem: Problem, routes: list[Route], settings: OptimizeSettings,
                 route_settings: RouteSettings, solver: str = "auto"):
        self.problem, self.settings, self.rs, self.solver = problem, settings, route_settings, solver
        self.routes = list(routes)
        self.sizes = [len(r.control) for r in routes]
        self.n_control = 2 * sum(self.sizes)
        self.L = problem.size
        self.walls = problem.walls
        self.positions: list[np.ndarray] | None = None  # each pose's last equilibrium (warm starts)
        self.eval_tol: float | None = None
        self.ik: SoftIK | None = None  # the robot of the last evaluation
        self._at: tuple | None = None  # the last point valued: z, its routes, their waypoints, shape gradients
        self.evaluations = 0

    # ------------------------------------------------------------ variables
    def pack(self, routes: list[Route], ratios: np.ndarray) -> np.ndarray:
        return np.concatenate([np.concatenate([r.control.ravel() for r in routes]) / self.L,
                               np.asarray(ratios, dtype=float).ravel()])

    def unpack(self, z: np.ndarray) -> tuple[list[Route], np.ndarray]:
        """The routes and ratios (P, T) at z."""
        z = np.asarray(z, dtype=float)
        c = z[:self.n_control].reshape(-1, 2) * self.L
        bounds = np.cumsum([0] + self.sizes)
        routes = [r.with_control(c[a:b]) for r, a, b in zip(self.routes, bounds[:-1], bounds[1:])]
        return routes, z[self.n_control:].reshape(self.problem.n_poses, len(self.routes))

    def bounds(self) -> so.Bounds:
        """Control points within the body's bounding box (an exit within its segment's),
        ratios within [-pmax, STROKE cmax]."""
        lo, hi = self.problem.mesh.nodes.min(axis=0) / self.L, self.problem.mesh.nodes.max(axis=0) / self.L
        n = sum(self.sizes)
        fs = self.problem.scene.fibers
        r = self.problem.n_poses * len(self.routes)
        low = np.r_[np.tile(lo, n), np.full(r, -fs.max_payout)]
        high = np.r_[np.tile(hi, n), np.full(r, STROKE * fs.max_contraction)]
        for last, route in zip(np.cumsum(self.sizes) - 1, self.routes):
            if route.exits:
                low[2 * last:2 * last + 2] = route.exit.min(axis=0) / self.L
                high[2 * last:2 * last + 2] = route.exit.max(axis=0) / self.L
        return so.Bounds(low, high)

    def on_exits(self) -> list[dict]:
        """Each exit kept on its segment: ``n . (e - a) = 0`` (n the segment's normal,
        a its first end, e the route's last control point), a linear equality."""
        out = []
        for last, route in zip(np.cumsum(self.sizes) - 1, self.routes):
            if not route.exits:
                continue
            a, b = route.exit
            t = (b - a) / max(float(np.linalg.norm(b - a)), 1e-300)
            row = np.zeros(self.n_control + self.problem.n_poses * len(self.routes))
            row[2 * last:2 * last + 2] = (-t[1], t[0])
            offset = float(row[2 * last:2 * last + 2] @ a) / self.L
            out.append({"type": "eq", "fun": lambda z, row=row, offset=offset: np.array([row @ z - offset]),
                        "jac": lambda z, row=row: row[None, :]})
        return out

    # ------------------------------------------------------------ the clearance constraint
    def clearance(self, z: np.ndarray, jacobian: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """``(d_i - c) / L`` (q,) for every waypoint of every route at z (>= 0: it keeps
        the clearance ``c``, the route's own where it is flagged,
        :func:`~.clearance.held_clearance`), and with ``jacobian`` its Jacobian
        w.r.t. z (q, len(z))."""
        routes, _ = self.unpack(z)
        values, rows, at = [], [], 0
        for r in routes:
            walls = route_walls(r, self.walls, self.rs.clearance)
            if jacobian:
                d, g = walls.distance_gradient(r.waypoints)
                # waypoint i is sum_j B_ij c_j, and z holds c / L: d(d_i / L)/dz_j = B_ij g_i
                J = np.zeros((len(d), len(z)))
                J[:, at:at + r.control.size] = (r.basis[:, :, None] * g[:, None, :]).reshape(len(d), -1)
                if r.exits:  # the lift moves with the exit, the last control point: d lift / d e = -d lift / d p
                    J[:, at + r.control.size - 2:at + r.control.size] -= walls.lift(r.waypoints)[1]
                rows.append(J)
            else:
                d = walls.distance(r.waypoints)
            values.append((d - held_clearance(r, self.rs.clearance)) / self.L)
            at += r.control.size
        return np.concatenate(values), (np.vstack(rows) if jacobian else None)

    # ------------------------------------------------------------ evaluation
    def soft_ik(self, routes: list[Route]) -> SoftIK:
        """The as-built robot of these routes, warm started from the last positions:
        the last one's models with their cables moved (the routes keep their
        waypoint counts), else a new one."""
        last = self.ik
        cables = tendon_cables(self.problem, [r.tendon() for r in routes],
                               None if last is None else last.model.cables.points.tri)
        if last is not None and np.array_equal(cables.start, last.model.cables.start):
            retriangulated = not np.array_equal(cables.points.tri, last.model.cables.points.tri)
            last.move_cables(cables)
            if retriangulated and self.positions is not None:  # as a new robot would start
                for ps, x in zip(last.poses, self.positions):
                    ps.model.set_positions(x)
            return last
        ik = SoftIK(self.problem, self.settings, self.solver, cables=cables)
        if self.eval_tol is not None:
            ik.eval_tol = self.eval_tol
        if self.positions is not None:
            for ps, x in zip(ik.poses, self.positions):
                ps.model.set_positions(x)
        self.ik = ik
        return ik

    def evaluate(self, z: np.ndarray) -> tuple[float, np.ndarray]:
        """O and dO/dz at z; raises ConvergenceError when an equilibrium fails or a
        route has shrunk to a point (``COLLAPSED``)."""
        return self.value(z), self.gradient(z)

    @probe()
    def value(self, z: np.ndarray) -> float:
        """O at z, each pose's equilibrium solved; its gradient by :meth:`gradient`.
        Raises as :meth:`evaluate` does."""
        routes, ratios = self.unpack(z)
        points = [r.waypoints for r in routes]
        if min(polyline_length(p) for p in points) <= COLLAPSED * self.L:
            raise ConvergenceError("a route has shrunk to a point")
        self._at = None
        ik = self.soft_ik(routes)
        f = ik.value(ratios.ravel())
        self.positions = [ps.model.positions() for ps in ik.poses]
        ff, gf = shape_cost(points, self.rs)
        self._at = (np.array(z), routes, points, gf)
        self.evaluations += 1
        return f + ff

    def gradient(self, z: np.ndarray) -> np.ndarray:
        """dO/dz at z: the adjoint solves at the last point :meth:`value` evaluated
        where that is z, else at z evaluated anew."""
        if self._at is None or not np.array_equal(z, self._at[0]):
            self.value(z)
        _, routes, points, gf = self._at
        ik = self.ik
        g_r = ik.gradient()
        gX = np.zeros((ik.model.P, 2))
        for ps, lam in zip(ik.poses, ik.adjoints):
            gX -= rest_point_gradient(ps.model, lam)
        gX += np.concatenate(gf)
        g_c, at = [], 0
        for r, p in zip(routes, points):
            g_c.append(r.basis.T @ gX[at:at + len(p)])
            at += len(p)
        return np.concatenate([np.concatenate(g_c).ravel() * self.L, g_r])


def _on_segment(route: Route) -> Route:
    """A route whose exit SLSQP left a rounding error off its segment, with its exit on it."""
    if not route.exits:
        return route
    a, b = route.exit
    ab = b - a
    t = np.clip((route.control[-1] - a) @ ab / max(float(ab @ ab), 1e-300), 0.0, 1.0)
    control = route.control.copy()
    control[-1] = a + t * ab
    return route.with_control(control)


@dataclass
class RoutedLayout:
    """The outcome of :func:`optimize_routes`: the routes, each pose's ratios (P, T),
    the objective before and after, and the count of evaluations."""

    routes: list[Route]
    ratios: np.ndarray
    objective_start: float
    objective: float
    evaluations: int
    message: str


@probe()
def optimize_routes(context: Context, routes: list[Route], ratios: np.ndarray, route_settings: RouteSettings,
                    positions=None, on_iteration=None) -> RoutedLayout:
    """Minimize O subject to the clearance (module docstring) on the context's
    problem, with its settings and solver (its state is not used), from ``routes``
    and ``ratios`` (P, T) by SLSQP, warm started from ``positions`` (each pose's
    equilibrium, (n, 2)) where given; returns the best point evaluated that keeps the
    clearance (within ``CLEAR_TOL``), or the best of all where none does.
    ``on_iteration(k, objective)`` is called per iteration."""
    obj = RouteObjective(context.problem, routes, context.settings, route_settings, context.solver)
    obj.positions = None if positions is None else [np.asarray(x) for x in positions]
    z0 = obj.pack(routes, ratios)
    best = {"f": np.inf, "z": z0}  # the best point that keeps the clearance ...
    lowest = {"f": np.inf, "z": z0}  # ... and the best of all, should none keep it
    last: dict = {}
    margin = -CLEAR_TOL * route_settings.clearance / obj.L
    kept: dict = {}

    def clearance(z):  # the constraint's values at z, once per point (SLSQP asks after fun did)
        if "z" not in kept or not np.array_equal(z, kept["z"]):
            kept.update(z=np.array(z), values=obj.clearance(z, jacobian=False)[0])
        return kept["values"]

    def fun(z):
        if "z" in last and np.array_equal(z, last["z"]):  # SLSQP starts where we did
            return last["f"]
        try:
            f = obj.value(z)
        except ConvergenceError:  # an equilibrium that fails is a step too far: make it look bad
            f0 = lowest["f"] if np.isfinite(lowest["f"]) else 1.0
            last.update(z=np.array(z), f=10.0 * abs(f0) + 1.0, failed=True)
            return last["f"]
        last.update(z=np.array(z), f=f, failed=False)
        if f < lowest["f"]:
            lowest.update(f=f, z=np.array(z))
        if f < best["f"] and clearance(z).min() >= margin:
            best.update(f=f, z=np.array(z))
        return f

    def jac(z):  # SLSQP asks at the point its line search accepted, the last one fun valued
        if "z" in last and np.array_equal(z, last["z"]) and last["failed"]:
            return np.zeros_like(z)
        try:
            return obj.gradient(z)
        except ConvergenceError:
            return np.zeros_like(z)

    f_start = fun(z0)
    it = {"k": 0}

    def callback(xk):
        it["k"] += 1
        if on_iteration is not None:
            on_iteration(it["k"], best["f"])

    constraint = {"type": "ineq", "fun": clearance, "jac": lambda z: obj.clearance(z)[1]}
    res = so.minimize(fun, z0, jac=jac, method="SLSQP", bounds=obj.bounds(), constraints=[constraint] + obj.on_exits(),
                      callback=callback, options={"maxiter": route_settings.iterations, "ftol": 1e-12})
    found = best if np.isfinite(best["f"]) else lowest
    out_routes, out_ratios = obj.unpack(found["z"])
    out_routes = [_on_segment(r) for r in out_routes]
    return RoutedLayout(out_routes, out_ratios, objective_start=float(f_start), objective=float(found["f"]),
                        evaluations=obj.evaluations, message=str(res.message))

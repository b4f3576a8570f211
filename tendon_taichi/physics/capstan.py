"""Capstan friction of tendons in their channels (``docs/method.md``, friction).

A tendon is pulled in at its pull end (its last point) and slides through its
waypoints toward its anchor (its first point). At an interior waypoint that
turns it by ``theta_j``, Coulomb friction with coefficient ``mu`` costs a
factor ``exp(-mu |theta_j|)`` of tension, so segment ``s`` carries

    T_s = tau w_s,   w_s = exp(-mu Theta_s),   Theta_s = sum_{j >= s} |theta_j|

(``theta_j`` the turn at the joint after segment ``j``, in the deformed
state; the last segment pulls with the full ``tau``). The model keeps ``w``
frozen inside a Newton step, which makes the cable conservative with weighted
length ``L_w = sum_s w_s l_s`` and weighted rest length
``a = rho (a0 - ac)``, ``rho = sum_s w_s l0_s / sum_s l0_s``, and updates
``w`` from the new angles between steps (:class:`Capstan`); at the fixed
point the forces are the frictional ones. ``mu = 0`` never builds a
:class:`Capstan`: the frictionless cable is untouched.

The equilibrium's true Jacobian adds to the frozen-weight Hessian ``H`` the
term of the weights' own dependence on ``x``,

    E = sum_s (dR/dw_s) (dw_s/dx)^T,
    dR/dw_s = tau g_s + (dtau/dw_s) G,   G = sum_t w_t g_t,   g_s = dl_s/dx,

which is not symmetric: :class:`FrictionJacobian` applies ``E`` and
``E^T`` (numpy, O(segments)) for the adjoint and the sensitivities.

``|theta|`` has a kink at a straight joint, and the joints of a straight run of
waypoints in one triangle stay straight under its affine deformation, with a
``theta`` of round-off (about 1e-15). There ``E`` takes the derivative that
central differences see, ``d|theta|/dtheta = 0``, for every ``|theta|`` below
:data:`STRAIGHT`, instead of a sign that the last bits of the state choose.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..body.cables import CableSet


#: a joint that turns by less than this (rad) is straight to :class:`FrictionJacobian`
#: (module docstring): far above the round-off of a straight joint's angle, and far below
#: any turn whose friction (a factor ``exp(-mu theta)``) could matter
STRAIGHT = 1e-10


def perp(v: np.ndarray) -> np.ndarray:
    """The vectors (k, 2) turned by +90 degrees."""
    return np.stack([-v[:, 1], v[:, 0]], axis=1)


class Capstan:
    """The static structure of a cable set's capstan friction: which segments
    meet at a joint, each cable's rest segment lengths ``l0`` (S,) m, and ``mu``.
    Positions go in as the cables' embedded points (P, 2)."""

    def __init__(self, cables: CableSet, rest_points: np.ndarray, mu: float):
        self.mu = float(mu)
        self.seg = cables.segments
        self.start = cables.start
        S, C = cables.n_segments, cables.n_cables
        self.cable = np.repeat(np.arange(C), np.diff(cables.start))
        #: segment s has a joint after it (the next segment is the same cable's)
        self.joint = np.zeros(S, dtype=bool)
        if S:
            self.joint[:-1] = self.cable[1:] == self.cable[:-1]
            if np.any(self.seg[1:, 0][self.joint[:-1]] != self.seg[:-1, 1][self.joint[:-1]]):
                raise ValueError("capstan friction needs each cable to be one polyline")
        self.l0 = np.linalg.norm(rest_points[self.seg[:, 1]] - rest_points[self.seg[:, 0]], axis=1)
        self.l0_sum = np.bincount(self.cable, self.l0, minlength=C)

    def cable_suffix_sum(self, v: np.ndarray) -> np.ndarray:
        """Per segment s, the sum of v over the segments s, s+1, ... of its cable."""
        r = np.concatenate([np.cumsum(v[::-1])[::-1], [0.0]])
        return r[:-1] - r[self.start[1:]][self.cable]

    def cable_prefix_sum(self, v: np.ndarray) -> np.ndarray:
        """Per segment s, the sum of v over the segments of its cable up to s."""
        c = np.concatenate([[0.0], np.cumsum(v)])
        return c[1:] - c[self.start[:-1]][self.cable]

    def state(self, points: np.ndarray) -> "CapstanState":
        """Angles, weights and the factor rho at deformed points (P, 2)."""
        d = points[self.seg[:, 1]] - points[self.seg[:, 0]]
        l = np.linalg.norm(d, axis=1)
        theta = np.zeros(len(d))
        j = np.flatnonzero(self.joint)
        a, b = d[j], d[j + 1]
        theta[j] = np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], (a * b).sum(axis=1))
        Theta = self.cable_suffix_sum(np.abs(theta))
        w = np.exp(-self.mu * Theta)
        rho = np.bincount(self.cable, w * self.l0, minlength=len(self.l0_sum)) / self.l0_sum
        return CapstanState(points, d, l, theta, Theta, w=w, rho=rho)


@dataclass(frozen=True)
class CapstanState:
    """At deformed points (P, 2): segment vectors ``d`` (S, 2) and lengths ``l``
    (S,), the signed turn ``theta`` (S,) at the joint after each segment (0 where
    none), the turning ``Theta`` (S,) between each segment and the pull end, the
    weights ``w`` (S,) and the factors ``rho`` (C,)."""

    points: np.ndarray
    d: np.ndarray
    l: np.ndarray
    theta: np.ndarray
    Theta: np.ndarray
    w: np.ndarray
    rho: np.ndarray

    @cached_property
    def n(self) -> np.ndarray:
        """Unit segment directions (S, 2)."""
        return self.d / np.maximum(self.l, 1e-300)[:, None]

    @cached_property
    def dphi(self) -> np.ndarray:
        """d(direction angle)/d(segment vector) per segment, perp(d) / l^2 (S, 2)."""
        return perp(self.d) / np.maximum(self.l * self.l, 1e-300)[:, None]


def _scatter(index: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """(n, 2): the rows of ``values`` (k, 2) summed into rows ``index`` (k,), in
    order - ``np.add.at`` on zeros, the same sums, by ``np.bincount``."""
    return np.stack([np.bincount(index, values[:, 0], minlength=n),
                     np.bincount(index, values[:, 1], minlength=n)], axis=1)


class PointMap:
    """Moves vectors between mesh nodes and embedded points: ``to_points(v)``
    interpolates node vectors (n, 2) at the points, ``to_nodes(q)`` spreads point
    vectors (P, 2) onto the nodes (its transpose); clamped nodes get zero."""

    def __init__(self, triangles: np.ndarray, tri: np.ndarray, bary: np.ndarray, fixed: np.ndarray):
        self.nodes = triangles[tri]  # (P, 3)
        self.bary = bary
        self.n = len(fixed)
        #: 1.0 on free nodes, 0.0 on clamped ones, (n, 1)
        self.free = (~np.asarray(fixed, dtype=bool)).astype(float)[:, None]

    def to_points(self, v: np.ndarray) -> np.ndarray:
        v = np.asarray(v, dtype=float).reshape(self.n, 2)
        return np.einsum("pk,pkd->pd", self.bary, v[self.nodes])

    def to_nodes(self, q: np.ndarray) -> np.ndarray:
        spread = (self.bary[:, :, None] * q[:, None, :]).reshape(-1, 2)
        return _scatter(self.nodes.ravel(), spread, self.n) * self.free


class FrictionJacobian:
    """``E``, the part of the equilibrium's Jacobian that the frozen weights leave
    out (module docstring), at one state: ``cap`` its capstan structure, ``st``
    the :class:`CapstanState`, per cable the tension ``tau``, ``kc = dtau/dL``,
    strain ``e`` and ``a0 - ac`` (``free_length``, m); ``pm`` the
    :class:`PointMap`. Products take and give node vectors (n, 2), zero on
    clamped nodes."""

    def __init__(self, cap: Capstan, st: CapstanState, tau, kc, e, free_length, pm: PointMap):
        self.cap, self.st, self.pm = cap, st, pm
        c = cap.cable
        self.tau_s = np.asarray(tau)[c]
        #: dtau/dw_s (S,): through L_w and through rho
        self.dtau_dw = np.asarray(kc)[c] * (st.l - (1.0 + np.asarray(e)[c]) * np.asarray(free_length)[c]
                                            * cap.l0 / cap.l0_sum[c])
        #: d|theta_j|/dtheta_j (S,): the sign of the turn, 0 at a straight joint
        self.sigma = np.where(np.abs(st.theta) < STRAIGHT, 0.0, np.sign(st.theta))

    # ------------------------------------------------------------ point-level pieces
    def segment_diff(self, V: np.ndarray) -> np.ndarray:
        """V_b - V_a per segment (S, 2) for point vectors V (P, 2)."""
        return V[self.cap.seg[:, 1]] - V[self.cap.seg[:, 0]]

    def segment_forces(self, coef: np.ndarray, vec: np.ndarray) -> np.ndarray:
        """Point vectors (P, 2) of sum_s coef_s (vec_s at b(s), -vec_s at a(s))."""
        f = coef[:, None] * vec
        seg = self.cap.seg
        # what np.add.at adds (the b ends, then the a ends), in the same order
        return _scatter(np.concatenate([seg[:, 1], seg[:, 0]]), np.concatenate([f, -f]), len(self.st.points))

    def joint_rates(self, V: np.ndarray) -> np.ndarray:
        """d theta_j (S,) for point displacements V (P, 2) (0 where no joint)."""
        r = (self.st.dphi * self.segment_diff(V)).sum(axis=1)  # d phi_s
        out = np.zeros_like(r)
        j = np.flatnonzero(self.cap.joint)
        out[j] = r[j + 1] - r[j]
        return out

    def joint_forces(self, c: np.ndarray) -> np.ndarray:
        """Point vectors (P, 2) of sum_j c_j d theta_j / d points."""
        dphi_coef = np.zeros_like(c)
        j = np.flatnonzero(self.cap.joint)
        dphi_coef[j + 1] += c[j]
        dphi_coef[j] -= c[j]
        return self.segment_forces(dphi_coef, self.st.dphi)

    def weight_rates(self, V: np.ndarray) -> np.ndarray:
        """d w_s (S,) for point displacements V (P, 2)."""
        return -self.cap.mu * self.st.w * self.cap.cable_suffix_sum(self.sigma * self.joint_rates(V))

    def weight_forces(self, alpha: np.ndarray) -> np.ndarray:
        """Point vectors (P, 2) of sum_s alpha_s d w_s / d points."""
        A = self.cap.cable_prefix_sum(alpha * self.st.w)
        return self.joint_forces(-self.cap.mu * self.sigma * A)

    # ------------------------------------------------------------ products
    def product(self, v: np.ndarray) -> np.ndarray:
        """E v (n, 2)."""
        cap, st = self.cap, self.st
        V = self.pm.to_points(v)
        omega = self.weight_rates(V)
        per_cable = np.bincount(cap.cable, omega * self.dtau_dw, minlength=len(cap.l0_sum))
        coef = omega * self.tau_s + per_cable[cap.cable] * st.w
        return self.pm.to_nodes(self.segment_forces(coef, st.n))

    def transpose_product(self, lam: np.ndarray) -> np.ndarray:
        """E^T lam (n, 2)."""
        cap, st = self.cap, self.st
        Lam = self.pm.to_points(lam)
        g_lam = (st.n * self.segment_diff(Lam)).sum(axis=1)  # g_s . lam
        G_lam = np.bincount(cap.cable, st.w * g_lam, minlength=len(cap.l0_sum))
        alpha = self.tau_s * g_lam + self.dtau_dw * G_lam[cap.cable]
        return self.pm.to_nodes(self.weight_forces(alpha))

    def tension_gradient(self, coef: np.ndarray) -> np.ndarray:
        """sum_c coef_c (dtau_c/dx through the weights) (n, 2): the part of the
        tensions' x-derivative that the frozen weights leave out."""
        return self.pm.to_nodes(self.weight_forces(np.asarray(coef)[self.cap.cable] * self.dtau_dw))

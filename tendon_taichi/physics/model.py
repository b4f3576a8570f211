"""The Taichi model of body + cables: the idealized robot (the fiber lattice)
or a realizable one (a few tendons).

A :class:`Model` uploads a mesh, its clamps, its material and a cable set
into the two buffers of :mod:`.layout` once, and gives numpy access to the
energy ``E_tot(x, ac)``, its gradient, exact and PSD-projected Hessian
products, the cable tensions and their derivatives, and the mixed products
``d2E/dx dac`` - the physics of :mod:`.forces`. Solvers (:mod:`tendon_taichi.solve`)
work on the same buffers, through the public attributes ``fb``, ``ib`` and
``serial``.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..body.cables import CableSet
from ..body.mesh import Mesh
from ..body.scene import Material
from ..probes import probe
from . import runtime
from .elements import check_elements, element_kernels
from .buffers import k_copy_nodes, k_read, k_read_int, k_read_ranges, k_write, k_write_int, k_write_ranges
from .capstan import Capstan, FrictionJacobian, PointMap
from .layout import Scalar, Slot, allocate, csr
from .runtime import ti


@dataclass(frozen=True)
class _BodyArrays:
    """What a model uploads of its mesh and material alone, the same for every model of
    them (the many tendon robots of one design): node positions ``X`` (n, dim) m,
    triangles ``T`` (m, 3), the node -> element-corner incidences (``ne_start``, ``ne``:
    :func:`~.layout.csr`), the inverse rest shape matrices ``Bm`` (m, 2, 2) 1/m, the
    volumes ``vol`` (m,) m^3 and the lumped node masses ``mass`` (n,) kg."""

    X: np.ndarray
    T: np.ndarray
    ne_start: np.ndarray
    ne: np.ndarray
    Bm: np.ndarray
    vol: np.ndarray
    mass: np.ndarray


#: per mesh, its :class:`_BodyArrays` per material (thickness and density)
_BODY: "weakref.WeakKeyDictionary[Mesh, dict]" = weakref.WeakKeyDictionary()


def _body_arrays(mesh: Mesh, mat: Material) -> _BodyArrays:
    """The :class:`_BodyArrays` of ``mesh`` and ``mat``, computed once per mesh and material."""
    per_mesh = _BODY.setdefault(mesh, {})
    key = (float(mat.thickness), float(mat.density))
    if key not in per_mesh:
        X, T = mesh.nodes.astype(np.float64), mesh.triangles.astype(np.int64)
        start, order = csr(T.ravel(), mesh.n_nodes)
        Dm = np.stack([X[T[:, 1]] - X[T[:, 0]], X[T[:, 2]] - X[T[:, 0]]], axis=2)
        mass = np.zeros(mesh.n_nodes)
        np.add.at(mass, T.ravel(), np.repeat(mat.density * mat.thickness * mesh.areas / 3.0, 3))
        arrays = _BodyArrays(X, T, start, order, np.linalg.inv(Dm), vol=mat.thickness * mesh.areas, mass=mass)
        for a in vars(arrays).values():
            a.flags.writeable = False
        per_mesh[key] = arrays
    return per_mesh[key]


class Model:
    """Body (mesh, clamps, material) plus cables, on Taichi.

    Parameters: ``mesh`` rest mesh; ``fixed`` bool (n,) clamped nodes;
    ``material``; ``cables``; ``eps`` the width of the unilateral energy's
    cubic zone (strain); ``parallel`` forces parallel (True) or serialized
    (False) loops, ``None`` picks by size and threads
    (:func:`~tendon_taichi.physics.runtime.parallel_threshold`).
    """

    def __init__(self, mesh: Mesh, fixed: np.ndarray, material: Material, cables: CableSet,
                 eps: float = 0.01, parallel: bool | None = None):
        check_elements(mesh.dim)
        runtime.ensure_init()
        self.mesh, self.material, self.cables, self.eps = mesh, material, cables, float(eps)
        self.fixed = np.asarray(fixed, dtype=bool)
        self.n, self.m = mesh.n_nodes, mesh.n_triangles
        self.S, self.C, self.P = cables.n_segments, cables.n_cables, len(cables.points)
        self.single = cables.single_segment
        #: the element kernels of the mesh's dimension (:mod:`.elements`)
        self.kernels = element_kernels(mesh.dim)
        if parallel is None:
            threshold = runtime.parallel_threshold()
            parallel = (not runtime.is_cpu()) or (threshold is not None and self.m + self.S >= threshold)
        self.parallel = bool(parallel)
        self.serial = not self.parallel
        self._upload()
        #: capstan friction of the cables (None: frictionless)
        self.capstan = Capstan(cables, cables.points.positions(mesh.triangles, mesh.nodes), cables.friction) \
            if cables.has_friction else None
        self.point_map = PointMap(mesh.triangles, cables.points.tri, cables.points.bary, self.fixed)
        #: the body's coarser meshes, finest first, made when first asked for (a
        #: geometric multigrid's hierarchy); None for a model not made from a problem
        self.coarser_meshes: Callable[[], list[Mesh]] | None = None

    @classmethod
    def from_problem(cls, problem, cables: CableSet | None = None,
                     parallel: bool | None = None) -> "Model":
        """The model of a :class:`~tendon_taichi.body.problem.Problem` with its fiber
        lattice (the idealized robot) or the given ``cables``."""
        model = cls(problem.mesh, problem.fixed, problem.material,
                    problem.fiber_cables if cables is None else cables,
                    eps=problem.scene.fibers.eps, parallel=parallel)
        model.coarser_meshes = problem.coarser_meshes
        return model

    # ------------------------------------------------------------ upload
    def _upload(self) -> None:
        host = allocate(self.n, self.m, self.S, self.C, self.P, single=self.single)
        self.offset = host.offset
        mesh, cab, mat = self.mesh, self.cables, self.material
        body = _body_arrays(mesh, mat)
        host.put_int("TRI", body.T)
        host.put_int("NE_START", body.ne_start)
        host.put_int("NE", body.ne)  # entry = 3 e + corner
        for name in ("X0", "X", "XT"):
            host.put_f64(name, body.X)
        host.put_f64("BM", body.Bm)
        host.put_f64("VOL", body.vol)
        host.put_f64("MASK", np.repeat((~self.fixed).astype(float)[:, None], 2, axis=1))
        self.node_mass = body.mass.copy()
        host.put_f64("FEXT", body.mass[:, None] * np.asarray(mat.gravity, dtype=float)[None, :])
        # cables
        host.put_int("PT_TRI", cab.points.tri)
        host.put_f64("PT_BARY", cab.points.bary)
        seg_cable = np.repeat(np.arange(self.C), np.diff(cab.start))
        host.put_int("SEG", np.column_stack([cab.segments, seg_cable]) if self.S else [])
        host.put_int("CAB_START", cab.start)
        host.put_f64("A0", cab.a0)
        host.put_f64("EA", cab.stiffness)
        host.put_f64("SEG_WT", np.ones(self.S))
        host.put_f64("RHO", np.ones(self.C))
        self._weights = np.ones(self.S)  # what SEG_WT holds (only the host writes it)
        start, ns = self._incidences(cab)
        host.put_int("NS_START", start)
        host.put_int("NS", ns)
        host.put_f64("NS_COEF", self._segment_coefficients(cab))
        so = self.offset["SCALARS"]
        host.fb[so + Scalar.MU], host.fb[so + Scalar.LAM], host.fb[so + Scalar.EPS] = mat.mu, mat.lam, self.eps
        host.fb[so + Scalar.FLOOR] = 1e-10 * mat.mu * mat.thickness
        self.Bm = body.Bm.copy()
        self.vol = body.vol.copy()
        #: the f64 and i32 buffers (see :mod:`.layout`)
        self.fb = ti.ndarray(ti.f64, len(host.fb))
        self.ib = ti.ndarray(ti.i32, len(host.ib))
        #: the last gradient dE/dx as the host sees it, (2n,) N
        self.last_gradient = np.zeros(2 * self.n)
        self._sums_checked = (None, 0)  # the last scatter hessian_sums checked, and its bins
        #: the buffers' memory as numpy arrays where it is the host's (CPU backend;
        #: else None: the copy kernels move the arrays)
        self._fb_host, self._ib_host = runtime.host_view(self.fb), runtime.host_view(self.ib)
        # filled through the host's view where there is one: a copy, where from_numpy launches a
        # kernel (with :func:`_body_arrays`; the same bytes, and a level-3 design makes about 600)
        if self._fb_host is not None and self._ib_host is not None:
            self._fb_host[:] = host.fb
            self._ib_host[:] = host.ib
        else:
            self.fb.from_numpy(host.fb)
            self.ib.from_numpy(host.ib.astype(np.int32))

    def _incidences(self, cab: CableSet) -> tuple[np.ndarray, np.ndarray]:
        """The node <- segment incidences (end b with +bary, end a with -bary) in CSR
        form: row starts (n+1,) and the segment of each entry (6 S,); keeps their
        order for :meth:`_segment_coefficients`."""
        T = self.mesh.triangles.astype(np.int64)
        pt_nodes = T[cab.points.tri] if self.P else np.zeros((0, 3), np.int64)
        nodes = np.concatenate([pt_nodes[cab.segments[:, e]].ravel() for e in (0, 1)])
        segs = np.tile(np.repeat(np.arange(self.S), 3), 2)
        start, self._ns_order = csr(nodes, self.n)
        return start, segs[self._ns_order]

    def _segment_coefficients(self, cab: CableSet) -> np.ndarray:
        """The signed barycentric weight of every node-segment entry, in CSR order."""
        if not self.S:
            return np.zeros(0)
        coefs = np.concatenate([s * cab.points.bary[cab.segments[:, e]].ravel() for e, s in ((0, -1.0), (1, 1.0))])
        return coefs[self._ns_order]

    def move_cables(self, cables: CableSet) -> None:
        """Replace the cables by ``cables`` of the same structure (points, segments,
        cables and friction; a route moved), in place; the positions and
        contractions stay. Where a point moved to another triangle, the incidences
        are rebuilt and the capstan weights start again from 1, as in a new model."""
        old = self.cables
        if (not np.array_equal(cables.segments, old.segments) or cables.points.tri.shape != old.points.tri.shape
                or not np.array_equal(cables.start, old.start) or cables.friction != old.friction):
            raise ValueError("move_cables needs cables of the same structure")
        moved = not np.array_equal(cables.points.tri, old.points.tri)
        self.cables = cables
        if moved:
            start, ns = self._incidences(cables)
            for name, values in (("PT_TRI", cables.points.tri), ("NS_START", start), ("NS", ns)):
                self.write_int(name, values)
            self._weights = np.ones(self.S)
            self.write_many([("SEG_WT", self._weights), ("RHO", np.ones(self.C))])
        self.write("PT_BARY", cables.points.bary)
        self.write("NS_COEF", self._segment_coefficients(cables))
        self.write("A0", cables.a0)
        self.capstan = Capstan(cables, cables.points.positions(self.mesh.triangles, self.mesh.nodes),
                               cables.friction) if cables.has_friction else None
        self.point_map = PointMap(self.mesh.triangles, cables.points.tri, cables.points.bary, self.fixed)

    # ------------------------------------------------------------ host access to the buffers
    def read(self, name: str, count: int, at: int = 0) -> np.ndarray:
        """``count`` entries of f64 array ``name`` from entry ``at``, (count,)."""
        start = self.offset[name] + at
        if self._fb_host is not None:
            return self._fb_host[start:start + count].copy()
        out = np.empty(count, dtype=np.float64)
        if count:
            k_read(self.fb, start, out)
        return out

    def write(self, name: str, values: np.ndarray, at: int = 0) -> None:
        """Write ``values`` into f64 array ``name`` from entry ``at``."""
        v = np.ascontiguousarray(values, dtype=np.float64).ravel()
        start = self.offset[name] + at
        if self._fb_host is not None:
            self._fb_host[start:start + len(v)] = v
        elif len(v):
            k_write(self.fb, start, v)

    def write_int(self, name: str, values: np.ndarray, at: int = 0) -> None:
        """Write ``values`` into i32 array ``name`` from entry ``at``."""
        v = np.ascontiguousarray(values, dtype=np.int32).ravel()
        start = self.offset[name] + at
        if self._ib_host is not None:
            self._ib_host[start:start + len(v)] = v
        elif len(v):
            k_write_int(self.ib, start, v)

    def read_many(self, items: list[tuple[str, int]]) -> list[np.ndarray]:
        """Several arrays (name, count) in one copy (one kernel launch off the CPU)."""
        if self._fb_host is not None:
            return [self._fb_host[self.offset[n]:self.offset[n] + c].copy() for n, c in items]
        counts = [c for _, c in items]
        dst = np.concatenate([[0], np.cumsum(counts)])
        ranges = np.array([[self.offset[n], c, d] for (n, c), d in zip(items, dst[:-1])], dtype=np.int32)
        out = np.empty(int(dst[-1]), dtype=np.float64)
        if len(out):
            k_read_ranges(self.fb, ranges, out)
        return [out[a:b] for a, b in zip(dst[:-1], dst[1:])]

    def write_many(self, items: list[tuple[str, np.ndarray]]) -> None:
        """Several arrays (name, values) written at once (one kernel launch off the CPU)."""
        values = [np.ascontiguousarray(v, dtype=np.float64).ravel() for _, v in items]
        if self._fb_host is not None:
            for (n, _), v in zip(items, values):
                self._fb_host[self.offset[n]:self.offset[n] + len(v)] = v
            return
        counts = [len(v) for v in values]
        at = np.concatenate([[0], np.cumsum(counts)])
        ranges = np.array([[self.offset[n], c, a] for (n, _), c, a in zip(items, counts, at[:-1])], dtype=np.int32)
        if at[-1]:
            k_write_ranges(self.fb, ranges, np.concatenate(values))

    def read_int(self, name: str, at: int = 0) -> int:
        """Entry ``at`` of the i32 array ``name``."""
        if self._ib_host is not None:
            return int(self._ib_host[self.offset[name] + at])
        return int(k_read_int(self.ib, self.offset[name] + at))

    def node_vectors(self, name: str) -> np.ndarray:
        """The per-node vectors of array ``name`` (n, dim)."""
        return self.read(name, 2 * self.n).reshape(self.n, 2)

    # ------------------------------------------------------------ state
    @property
    def dofs(self) -> int:
        """Number of free degrees of freedom."""
        return int(2 * (~self.fixed).sum())

    def positions(self) -> np.ndarray:
        """Current node positions x (n, dim), m."""
        return self.node_vectors("X")

    def set_positions(self, x: np.ndarray) -> None:
        """Set node positions (n, dim); clamped nodes are reset to their rest position."""
        x = np.array(x, dtype=np.float64).reshape(self.n, 2)
        x[self.fixed] = self.mesh.nodes[self.fixed]
        self.write("X", x)

    def set_free_positions(self, x: np.ndarray) -> None:
        """Set all node positions, clamped ones included (for derivative checks)."""
        self.write("X", np.asarray(x, dtype=np.float64).reshape(self.n, 2))

    def reset(self) -> None:
        """Back to the rest positions."""
        k_copy_nodes(self.fb, self.ib, Slot.X0, Slot.X, self.serial)

    def contraction(self) -> np.ndarray:
        """Cable contractions ac (C,), m."""
        return self.read("AC", self.C)

    def set_contraction(self, ac: np.ndarray) -> None:
        """Set cable contractions ac (C,), m; the rest length a0 - ac must stay positive."""
        ac = np.asarray(ac, dtype=np.float64).reshape(self.C)
        if np.any(ac >= self.cables.a0):
            raise ValueError("a contraction reaches the cable's rest length")
        self.write("AC", ac)

    # ------------------------------------------------------------ energy and derivatives
    def energy_and_min_det(self, trial: bool = False) -> tuple[float, float]:
        """E_tot (J) and the smallest det F at the positions (``trial``: at the line
        search's trial positions)."""
        E, jmin = self.kernels.k_energy(self.fb, self.ib, Slot.XT if trial else Slot.X, self.serial)
        return float(E), float(jmin)

    def energy(self, x: np.ndarray | None = None) -> float:
        """E_tot (J) at x (default: the current positions); +inf if a triangle is inverted."""
        if x is not None:
            self.write("XT", np.asarray(x, dtype=np.float64).reshape(self.n, 2))
        E, jmin = self.energy_and_min_det(trial=x is not None)
        return E if jmin > 0.0 else float("inf")

    def gradient_norm2(self) -> float:
        """Computes the gradient G at the positions (kept on the host as
        :attr:`last_gradient`); returns |G|^2 over the free DOFs."""
        return float(self.kernels.k_gradient(self.fb, self.ib, self.last_gradient, self.serial))

    def gradient(self, x: np.ndarray | None = None) -> np.ndarray:
        """dE_tot/dx (n, dim), N, at x (default: current positions), all nodes; a given
        x becomes the current positions."""
        if x is not None:
            self.set_free_positions(x)
        self.gradient_norm2()
        return self.last_gradient.reshape(self.n, 2).copy()

    @probe("prepare")
    def prepare_hessian(self, project: bool = False, jacobi: bool = True) -> None:
        """Element tangents (exact or PSD-projected), cable stiffnesses and (``jacobi``)
        the block-Jacobi preconditioner at the current x."""
        self.kernels.k_hessian(self.fb, self.ib, 1 if project else 0, bool(jacobi), self.serial)

    def hessian_product(self, v: np.ndarray, project: bool = False,
                        prepare: bool = True) -> np.ndarray:
        """H v (n, dim) for v (n, dim): the exact (or projected) Hessian of E_tot at x."""
        if prepare:
            self.prepare_hessian(project)
        self.write("VIN", np.asarray(v, dtype=np.float64).reshape(self.n, 2))
        self.kernels.k_hessian_product(self.fb, self.ib, self.serial)
        return self.node_vectors("VOUT")

    def cable_state(self) -> dict[str, np.ndarray]:
        """Per cable at the current x: (weighted) length ``L`` (m), rest length ``a``
        (m), strain ``e``, tension ``tau`` (N, at the pull end), ``kc`` = dtau/dL
        (N/m), ``tau_ac`` = dtau/dac (N/m), contraction ``ac`` (m)."""
        self.kernels.k_update_cables(self.fb, self.ib, self.serial)
        C = self.C
        L, ac, tau, kc, tau_ac, rho = self.read_many([("L", C), ("AC", C), ("TAU", C), ("KC", C),
                                                      ("TAU_AC", C), ("RHO", C)])
        a = rho * (self.cables.a0 - ac)
        return {"L": L, "a": a, "e": L / a - 1.0, "tau": tau, "kc": kc, "tau_ac": tau_ac, "ac": ac}

    # ------------------------------------------------------------ capstan friction
    def cable_points(self, x: np.ndarray | None = None) -> np.ndarray:
        """Positions (P, 2) of the cables' embedded points at x (default: current)."""
        x = self.positions() if x is None else np.asarray(x, dtype=float).reshape(self.n, 2)
        return self.cables.points.positions(self.mesh.triangles, x)

    def update_friction(self) -> float:
        """Set the capstan weights from the current positions (frictionless cables: no
        change); returns the largest change of a weight."""
        if self.capstan is None:
            return 0.0
        st = self.capstan.state(self.cable_points())
        change = float(np.abs(st.w - self._weights).max(initial=0.0))
        self._weights = np.array(st.w, dtype=np.float64)
        self.write_many([("SEG_WT", self._weights), ("RHO", st.rho)])
        return change

    def segment_tensions(self) -> np.ndarray:
        """Tension (S,) N of every segment at the current x: tau w_s."""
        self.kernels.k_update_cables(self.fb, self.ib, self.serial)
        tau, w = self.read_many([("TAU", self.C), ("SEG_WT", self.S)])
        return tau[np.repeat(np.arange(self.C), np.diff(self.cables.start))] * w

    def friction_jacobian(self) -> FrictionJacobian | None:
        """The non-symmetric part of the equilibrium's Jacobian at the current x
        (:mod:`.capstan`), None without friction."""
        if self.capstan is None:
            return None
        cs = self.cable_state()
        st = self.capstan.state(self.cable_points())
        return FrictionJacobian(self.capstan, st, cs["tau"], cs["kc"], cs["e"], free_length=self.cables.a0 - cs["ac"],
                                pm=self.point_map)

    def tensions(self) -> np.ndarray:
        """Cable tensions tau (C,), N, at the current x."""
        self.kernels.k_update_cables(self.fb, self.ib, self.serial)
        return self.read("TAU", self.C)

    def tensions_at(self, ac: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Cable tensions tau (C,), N, at contractions ``ac`` (C,) m and positions ``x``
        (n, dim) m, which become the model's state (no solve: ``x`` is an equilibrium
        found before)."""
        self.set_contraction(ac)
        self.set_positions(x)
        return self.tensions()

    def length_jacobian_product(self, w: np.ndarray) -> np.ndarray:
        """sum_c w_c dL_c/dx, (n, dim), for w (C,)."""
        self.write("CCOEF", np.asarray(w, dtype=np.float64).reshape(self.C))
        self.kernels.k_cables_to_nodes(self.fb, self.ib, self.serial)
        return self.node_vectors("VOUT")

    def length_jacobian_transpose_product(self, v: np.ndarray) -> np.ndarray:
        """dL_c/dx . v, (C,), for v (n, dim)."""
        self.write("VIN", np.asarray(v, dtype=np.float64).reshape(self.n, 2))
        self.kernels.k_nodes_to_cables(self.fb, self.ib, self.serial)
        return self.read("CW", self.C)

    def mixed_product(self, w: np.ndarray) -> np.ndarray:
        """(d2E/dx dac) w, (n, dim), for w (C,) in m."""
        tau_ac = self.cable_state()["tau_ac"]
        return self.length_jacobian_product(tau_ac * np.asarray(w, dtype=np.float64))

    def mixed_transpose_product(self, v: np.ndarray) -> np.ndarray:
        """(d2E/dx dac)^T v, (C,), for v (n, dim)."""
        tau_ac = self.cable_state()["tau_ac"]
        return tau_ac * self.length_jacobian_transpose_product(v)

    # ------------------------------------------------------------ what the direct backend assembles
    def hessian_entries(self) -> np.ndarray:
        """Element and segment Hessian blocks as last prepared, (36 m + 144 S,):
        see :func:`~tendon_taichi.physics.self.kernels.k_hessian_entries`."""
        out = np.empty(36 * self.m + 144 * self.S)
        self.kernels.k_hessian_entries(self.fb, self.ib, out, self.serial)
        return out

    @probe("assembly")
    def hessian_sums(self, scatter: np.ndarray, bins: int) -> np.ndarray:
        """The :meth:`hessian_entries` summed into ``bins`` bins, entry k into bin
        ``scatter[k]`` (int32, (36 m + 144 S,), each < ``bins``): what
        ``np.bincount(scatter, weights=self.hessian_entries(), minlength=bins)`` gives,
        to the bit, (bins,); see :func:`~tendon_taichi.physics.self.kernels.k_hessian_sums`.
        ``scatter`` is checked at its first call: change none in place after it."""
        if self._sums_checked[0] is not scatter or self._sums_checked[1] != bins:
            # the kernel does not check its indices: each array once (the direct backend
            # makes a new one where its pattern changes, never changes one in place)
            if scatter.dtype != np.int32 or scatter.shape != (36 * self.m + 144 * self.S,):
                raise ValueError("hessian_sums: scatter must be int32, one bin per Hessian entry")
            if len(scatter) and not 0 <= scatter.min() <= scatter.max() < bins:
                raise ValueError(f"hessian_sums: a bin outside 0..{bins - 1}")
            self._sums_checked = (scatter, bins)
        out = np.empty(bins)
        self.kernels.k_hessian_sums(self.fb, self.ib, np.ascontiguousarray(scatter), out)
        return out

    def hessian_data(self) -> dict[str, np.ndarray]:
        """What the direct backend assembles from (after prepare_hessian)."""
        m, S, C = self.m, self.S, self.C
        D, seg_n, seg_l, seg_w, tau, kc = self.read_many([("D", 16 * m), ("SEG_N", 2 * S), ("SEG_L", S),
                                                          ("SEG_WT", S), ("TAU", C), ("KC", C)])
        return {"D": D.reshape(m, 4, 4), "Bm": self.Bm, "vol": self.vol, "seg_n": seg_n.reshape(S, 2),
                "seg_l": seg_l, "seg_w": seg_w, "tau": tau, "kc": kc}

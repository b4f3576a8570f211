"""3D bodies: tetrahedral meshes (extrusion, orientation, import, location), the
surface walls and the cubic fiber lattice."""

import itertools

import meshio
import numpy as np
import pytest

from tendon_taichi.body.lattice3d import OFFSETS, cubic_lattice, segment_triangle_params
from tendon_taichi.body.surface import SurfaceWalls
from tendon_taichi.body.tets import TetMesh, extrude, oriented, point_triangle_distance, read_tet_mesh
from tendon_taichi.body.walls import Walls
from tendon_taichi.errors import SceneError

RECT = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]])
L_SHAPE = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.0, 1.0], [1.0, 2.0], [0.0, 2.0]])
HOLE = np.array([[0.3, 0.3], [0.7, 0.3], [0.7, 0.7], [0.3, 0.7]])
BOX = np.array([2.0, 1.0, 1.5])  # the extruded RECT, depth 1.5


@pytest.fixture(scope="module")
def box():
    return extrude(RECT, [], BOX[2], 0.5)


@pytest.fixture(scope="module")
def ell():
    return extrude(L_SHAPE, [HOLE], 0.5, 0.25)


def box_sdf(p, hi=BOX):
    """The analytic signed distance of points (q, 3) from the box [0, hi]: positive inside."""
    inner = np.minimum(p, hi - p).min(axis=1)
    outer = np.linalg.norm(np.maximum(np.maximum(-p, p - hi), 0.0), axis=1)
    return np.where(inner >= 0, inner, -outer)


def face_keys(tets):
    f = tets[:, [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]].reshape(-1, 3)
    return np.unique(np.sort(f, axis=1), axis=0, return_counts=True)


def face_normals(mesh):
    p = mesh.nodes[mesh.boundary_faces]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return p, n


# --- extrusion -------------------------------------------------------------------------

@pytest.mark.parametrize("outline, holes, area, depth, edge", [
    (RECT, [], 2.0, 1.5, 0.5),
    (L_SHAPE, [HOLE], 3.0 - 0.16, 0.5, 0.25),
])
def test_extrude_volume_conformity_and_closed_outward_surface(outline, holes, area, depth, edge):
    mesh = extrude(outline, holes, depth, edge)
    assert isinstance(mesh, TetMesh) and mesh.dim == 3 and mesh.simplices is mesh.tetrahedra
    assert mesh.n_tetrahedra == len(mesh.tetrahedra) and mesh.n_nodes == len(mesh.nodes)
    assert mesh.volumes.min() > 0
    assert mesh.volumes.sum() == pytest.approx(area * depth, rel=1e-12)
    assert mesh.size == pytest.approx(np.linalg.norm(np.r_[np.ptp(outline, axis=0), depth]))
    _, counts = face_keys(mesh.tetrahedra)
    assert counts.max() <= 2
    assert (counts == 1).sum() == len(mesh.boundary_faces)
    # the surface is closed: every directed edge is matched by its reverse exactly once
    bf = mesh.boundary_faces
    e = np.concatenate([bf[:, [0, 1]], bf[:, [1, 2]], bf[:, [2, 0]]])
    directed = set(map(tuple, e))
    assert len(directed) == len(e)
    assert all((b, a) in directed for a, b in directed)
    # outward: the divergence theorem gives back the volume
    p, n = face_normals(mesh)
    assert np.einsum("fd,fd->", p.mean(axis=1), n) / 6.0 == pytest.approx(area * depth, rel=1e-12)
    # no face is doubled or split unmatched inside: the surface area is the analytic one
    perimeter = sum(np.linalg.norm(np.roll(q, -1, axis=0) - q, axis=1).sum() for q in (outline, *holes))
    assert 0.5 * np.linalg.norm(n, axis=1).sum() == pytest.approx(2 * area + perimeter * depth, rel=1e-12)


@pytest.mark.parametrize("depth, edge, layers", [
    (1.5, 0.5, 3), (1.0, 0.3, 4), (0.05, 1.0, 1), (1.1, 0.1, 11), (0.3, 0.1, 3)])
def test_extrude_layer_count(depth, edge, layers):
    mesh = extrude(0.1 * RECT, [], depth, edge)
    z = np.unique(mesh.nodes[:, 2])
    assert len(z) == layers + 1
    assert np.allclose(np.diff(z), depth / layers, rtol=1e-12)
    assert z[0] == 0.0 and z[-1] == pytest.approx(depth, rel=1e-15)


# --- orientation and import --------------------------------------------------------------

def test_oriented_flips_all_negative_and_drops_unused_nodes(box):
    nodes = np.concatenate([box.nodes, [[9.0, 9.0, 9.0]]])
    flipped = box.tetrahedra[:, [1, 0, 2, 3]]
    assert (TetMesh(nodes, flipped).volumes < 0).all()
    mesh = oriented(nodes, flipped, "test")
    assert mesh.n_nodes == box.n_nodes
    assert (mesh.volumes > 0).all()
    assert np.allclose(mesh.volumes, box.volumes, rtol=1e-12)


def test_oriented_rejects_mixed_and_flat(box, rng):
    tets = box.tetrahedra.copy()
    bad = rng.choice(len(tets), 5, replace=False)
    tets[bad] = tets[bad][:, [1, 0, 2, 3]]
    with pytest.raises(SceneError, match=f"test: 5 of {len(tets)} tetrahedra are inverted"):
        oriented(box.nodes, tets, "test")
    nodes = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.3, 0.3, 0]], dtype=float)
    with pytest.raises(SceneError, match="test: 1 degenerate"):
        oriented(nodes, [[0, 1, 2, 3], [0, 1, 2, 4]], "test")


def test_read_tet_mesh_round_trip(box, tmp_path):
    path = tmp_path / "body.vtu"
    meshio.write(path, meshio.Mesh(box.nodes, [("tetra", box.tetrahedra)]))
    mesh = read_tet_mesh(path)
    assert np.array_equal(mesh.tetrahedra, box.tetrahedra)
    assert np.allclose(mesh.nodes, box.nodes, rtol=0, atol=1e-15)
    mm = read_tet_mesh(path, scale=1e-3)
    assert np.allclose(mm.nodes, 1e-3 * box.nodes, rtol=1e-15)
    assert mm.volumes.sum() == pytest.approx(1e-9 * BOX.prod(), rel=1e-12)


def test_read_tet_mesh_errors(box, tmp_path):
    path = tmp_path / "skin.vtu"
    meshio.write(path, meshio.Mesh(box.nodes, [("triangle", box.boundary_faces)]))
    with pytest.raises(SceneError, match="has no tetrahedra"):
        read_tet_mesh(path)
    junk = tmp_path / "junk.msh"
    junk.write_bytes(bytes(np.random.default_rng(3).integers(0, 256, 400, dtype=np.uint8)))
    with pytest.raises(SceneError) as info:
        read_tet_mesh(junk)
    assert "\n" not in str(info.value) and str(info.value).startswith(f"cannot read mesh file '{junk}'")


# --- point-triangle distance -------------------------------------------------------------

def segment_distance(p, a, b):
    ab = b - a
    t = np.clip(((p - a) * ab).sum(1) / (ab * ab).sum(1), 0, 1)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def test_point_triangle_distance_against_dense_sampling(rng):
    k, n = 300, 120
    a, b, c = (rng.normal(size=(k, 3)) for _ in range(3))
    p = 1.5 * rng.normal(size=(k, 3))
    dist, closest = point_triangle_distance(p, a, b, c)
    assert np.allclose(np.linalg.norm(p - closest, axis=1), dist, rtol=1e-12)
    i, j = np.triu_indices(n + 1)
    u, v = (j - i) / n, i / n  # barycentric samples with u + v <= 1
    samples = a[:, None] + u[None, :, None] * (b - a)[:, None] + v[None, :, None] * (c - a)[:, None]
    dense = np.linalg.norm(samples - p[:, None], axis=2).min(axis=1)
    edges = np.minimum.reduce([segment_distance(p, a, b), segment_distance(p, b, c), segment_distance(p, c, a)])
    ref = np.minimum(dense, edges)
    spacing = np.maximum.reduce([np.linalg.norm(q, axis=1) for q in (b - a, c - a, c - b)]) / n
    assert (dist <= ref + 1e-12).all()
    assert (dist >= ref - spacing).all()
    # the closest point lies on the triangle: its barycentric weights are >= 0
    n_ = np.cross(b - a, c - a)
    area = (n_ * n_).sum(1)
    wb = (np.cross(closest - a, c - a) * n_).sum(1) / area
    wc = (np.cross(b - a, closest - a) * n_).sum(1) / area
    assert (wb >= -1e-9).all() and (wc >= -1e-9).all() and (wb + wc <= 1 + 1e-9).all()


def test_point_triangle_distance_regions(rng):
    k = 200
    a, b, c = (rng.normal(size=(k, 3)) for _ in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    s = rng.uniform(-1, 1, k)[:, None]
    # the face: a point inside the triangle lifted along the normal
    w = rng.dirichlet([1, 1, 1], k)
    foot = w[:, :1] * a + w[:, 1:2] * b + w[:, 2:] * c
    dist, closest = point_triangle_distance(foot + s * n, a, b, c)
    assert np.allclose(dist, np.abs(s[:, 0]), rtol=1e-10, atol=1e-12)
    assert np.allclose(closest, foot, atol=1e-10)
    # an edge: outward across each edge, in the plane and off it
    u = rng.uniform(0.01, 1, k)[:, None]
    for q0, q1 in ((a, b), (b, c), (c, a)):
        t = rng.uniform(0, 1, k)[:, None]
        out = np.cross(q1 - q0, n)
        out /= np.linalg.norm(out, axis=1, keepdims=True)
        foot = q0 + t * (q1 - q0)
        dist, closest = point_triangle_distance(foot + u * out + s * n, a, b, c)
        assert np.allclose(dist, np.hypot(u[:, 0], s[:, 0]), rtol=1e-10)
        assert np.allclose(closest, foot, atol=1e-10)
    # a vertex: out along minus the bisector of its two edges
    for v, q1, q2 in ((a, b, c), (b, c, a), (c, a, b)):
        e1 = (q1 - v) / np.linalg.norm(q1 - v, axis=1, keepdims=True)
        e2 = (q2 - v) / np.linalg.norm(q2 - v, axis=1, keepdims=True)
        away = -(e1 + e2) / np.linalg.norm(e1 + e2, axis=1, keepdims=True)
        dist, closest = point_triangle_distance(v + u * away + s * n, a, b, c)
        assert np.allclose(dist, np.hypot(u[:, 0], s[:, 0]), rtol=1e-10)
        assert np.allclose(closest, v, atol=1e-10)


# --- location ----------------------------------------------------------------------------

def test_locate_and_contains_box(box, rng):
    inside = rng.uniform(0, 1, (500, 3)) * BOX
    emb, dist = box.locate(inside)
    assert (dist == 0).all() and box.contains(inside, 0.0).all()
    assert np.allclose(emb.positions(box.tetrahedra, box.nodes), inside, atol=1e-12)
    assert (emb.bary >= 0).all() and np.allclose(emb.bary.sum(axis=1), 1)
    outside = rng.uniform(-1, 1, (500, 3)) * 2 * BOX + 0.5 * BOX
    outside = outside[box_sdf(outside) < -1e-6]
    emb, dist = box.locate(outside)
    assert np.allclose(dist, -box_sdf(outside), rtol=0, atol=1e-12)
    assert not box.contains(outside, 1e-7).any()
    assert (emb.bary >= 0).all() and np.allclose(emb.bary.sum(axis=1), 1)
    # beyond max_dist only "farther" is promised
    _, capped = box.locate(outside, max_dist=0.1)
    assert (capped >= dist - 1e-12).all() and (capped[dist <= 0.1] == dist[dist <= 0.1]).all()


# --- surface walls -----------------------------------------------------------------------

def test_surface_walls_distance_and_inside(box, rng):
    walls = SurfaceWalls.of(box)
    assert isinstance(walls, Walls)
    p = rng.uniform(-0.5, 1.5, (600, 3)) * BOX
    exact = box_sdf(p)
    assert np.allclose(walls.distance(p), exact, rtol=0, atol=1e-12)
    assert np.array_equal(walls.inside(p), exact >= 0)
    corners = np.array(list(itertools.product(*[(0.0, x) for x in BOX])))
    assert walls.inside(corners).all() and np.allclose(walls.distance(corners), 0, atol=1e-15)


def test_surface_walls_gradient(box, rng):
    walls = SurfaceWalls.of(box)
    p = rng.uniform(-0.5, 1.5, (400, 3)) * BOX
    h = 1e-6
    # away from the medial surface (where the gradient jumps) and from the walls
    gaps = np.sort(np.concatenate([p, BOX - p], axis=1), axis=1)
    inner_ok = (gaps[:, 0] > 10 * h) & (gaps[:, 1] - gaps[:, 0] > 10 * h)
    outer_ok = (box_sdf(p) < -10 * h)
    p = p[inner_ok | outer_ok]
    d, g = walls.distance_gradient(p)
    assert np.allclose(d, box_sdf(p), atol=1e-12)
    assert np.allclose(np.linalg.norm(g, axis=1), 1, rtol=1e-12)
    fd = np.stack([(walls.distance(p + e) - walls.distance(p - e)) / (2 * h) for e in h * np.eye(3)], axis=1)
    assert np.allclose(g, fd, atol=1e-6)
    # on a wall: the inward normal
    on = np.array([[1.0, 0.5, 0.0], [2.0, 0.3, 0.7], [0.4, 1.0, 1.0]])
    _, g = walls.distance_gradient(on)
    assert np.allclose(g, [[0, 0, 1], [-1, 0, 0], [0, -1, 0]], atol=1e-12)


def test_polyline_distance(box, ell):
    walls = SurfaceWalls.of(box)
    line = np.array([[0.3, 0.5, 0.75], [1.0, 0.45, 0.7], [1.7, 0.5, 0.75]])
    exact = box_sdf(line).min()  # the box's distance is concave: least at a vertex
    assert walls.polyline_distance(line) == pytest.approx(exact, abs=1e-12)
    out = np.array([[0.5, 0.5, 0.5], [2.5, 0.5, 0.5], [1.5, 0.6, 0.5]])
    assert walls.polyline_distance(out) == pytest.approx(-0.5, abs=1e-12)
    # past the L's re-entrant edge (x = y = 1): least mid-segment, sqrt(0.02) away
    walls = SurfaceWalls.of(ell)
    seg = np.array([[1.5, 0.3, 0.25], [0.2, 1.6, 0.25]])
    exact = np.sqrt(0.02)
    got = walls.polyline_distance(seg)
    assert exact - 1e-12 <= got <= exact * (1 + 1 / 31)
    # random segments grazing the re-entrant edge: within the documented bound of the exact least distance
    rng = np.random.default_rng(7)
    t = np.linspace(0, 1, 1001)
    for _ in range(12):
        c = np.array([1 - rng.uniform(0.02, 0.2), 1 - rng.uniform(0.02, 0.2), 0.25])
        along = np.array([1, -1, 0]) + rng.normal(scale=0.2, size=3) * [1, 1, 0.3]
        a, b = c + rng.uniform(0.2, 0.6) * along, c - rng.uniform(0.2, 0.6) * along
        got = walls.polyline_distance(np.stack([a, b]))
        dense = walls.distance(a + t[:, None] * (b - a)).min()  # >= the exact least distance
        exact_lo = dense - 0.5 * np.linalg.norm(b - a) / (len(t) - 1)  # <= it: the distance is 1-Lipschitz
        assert exact_lo - 1e-12 <= got <= dense * (1 + 1 / 31) + 1e-12
    # a dip out through the hole
    assert walls.polyline_distance(np.array([[0.1, 0.5, 0.25], [0.9, 0.5, 0.25]])) == pytest.approx(-0.2, abs=1e-12)


# --- cubic lattice -----------------------------------------------------------------------

def clip_to_box(p0, p1, lo, hi):
    """Liang-Barsky: the parameter interval (enter (s,), leave (s,)) of segments p0->p1
    (s, 2) inside the box [lo, hi]; empty where enter >= leave."""
    enter, leave = np.zeros(len(p0)), np.ones(len(p0))
    d = p1 - p0
    for axis in range(2):
        with np.errstate(divide="ignore", invalid="ignore"):
            ta, tb = (lo[axis] - p0[:, axis]) / d[:, axis], (hi[axis] - p0[:, axis]) / d[:, axis]
        still = d[:, axis] == 0
        within = (p0[:, axis] > lo[axis]) & (p0[:, axis] < hi[axis])
        enter = np.where(still, np.where(within, enter, 1.0), np.maximum(enter, np.minimum(ta, tb)))
        leave = np.where(still, np.where(within, leave, 0.0), np.minimum(leave, np.maximum(ta, tb)))
    return enter, leave


def test_segment_triangle_params(rng):
    s, f = 40, 50
    p0, p1 = rng.normal(size=(s, 3)), rng.normal(size=(s, 3))
    a, b, c = (0.7 * rng.normal(size=(f, 3)) for _ in range(3))
    seg, tri, ts = segment_triangle_params(p0, p1, a, b, c, tol=1e-12)
    # the reference: p0 + t (p1 - p0) = a + u (b - a) + v (c - a), solved pair by pair
    cols = [np.broadcast_to(x, (s, f, 3)) for x in ((p1 - p0)[:, None], -(b - a)[None], -(c - a)[None])]
    tuv = np.linalg.solve(np.stack(cols, axis=-1), (a[None] - p0[:, None])[..., None])[..., 0]
    t, u, v = tuv[..., 0], tuv[..., 1], tuv[..., 2]
    margin = np.minimum.reduce([t, 1 - t, u, v, 1 - u - v])
    clear = np.abs(margin) > 1e-9  # leave out pairs on the edge of a decision
    got = np.zeros((s, f), dtype=bool)
    got[seg, tri] = True
    assert len(seg) == got.sum() and (margin > 0)[clear].sum() > 20
    assert np.array_equal(got[clear], (margin > 0)[clear])
    assert np.allclose(ts, t[seg, tri], atol=1e-9)


def test_cubic_lattice_box():
    s = 0.25
    sides = np.array([4, 2, 6]) * s  # even multiples: the centred lattice meets every wall
    mesh = extrude(np.array([[0, 0], [sides[0], 0], sides[:2], [0, sides[1]]]), [], sides[2], 0.3)
    lat = cubic_lattice(mesh, s)
    n = np.round(sides / s).astype(int)
    assert len(lat.nodes) == np.prod(n + 1)
    expected = sum(np.prod(n + 1 - np.abs(o)) for o in OFFSETS)
    assert lat.n_fibers == expected
    steps = np.round((lat.nodes[lat.edges[:, 1]] - lat.nodes[lat.edges[:, 0]]) / s).astype(int)
    assert {tuple(o) for o in steps} == set(OFFSETS)
    assert np.allclose(np.sort(np.unique(np.round(lat.a0 / s, 9))), [1, np.sqrt(2), np.sqrt(3)])
    assert np.allclose(lat.embedding.positions(mesh.tetrahedra, mesh.nodes), lat.nodes, atol=1e-12)
    cos2 = lat.pairs.cos2
    assert cos2.min() >= -1e-12 and cos2.max() <= 1 + 1e-12


def test_cubic_lattice_avoids_the_hole(ell):
    lat = cubic_lattice(ell, 0.125)
    assert lat.n_fibers > 0
    t = np.linspace(0, 1, 9)
    a, b = lat.nodes[lat.edges[:, 0]], lat.nodes[lat.edges[:, 1]]
    samples = (a[:, None] + t[None, :, None] * (b - a)[:, None]).reshape(-1, 3)
    assert ell.contains(samples, 1e-9).all()
    # exactly: no fiber's plan view enters the hole or the L's missing quadrant
    eps = 1e-9
    for lo, hi in ((HOLE.min(axis=0), HOLE.max(axis=0)), (np.array([1.0, 1.0]), np.array([3.0, 3.0]))):
        enter, leave = clip_to_box(a[:, :2], b[:, :2], lo + eps, hi - eps)
        assert not (enter < leave).any()
    # the lattice does clip fibers there: some candidates would cross a hole corner
    assert lat.n_fibers < cubic_lattice(extrude(L_SHAPE, [], 0.5, 0.25), 0.125).n_fibers
    cos2 = lat.pairs.cos2
    assert cos2.min() >= -1e-12 and cos2.max() <= 1 + 1e-12

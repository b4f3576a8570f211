"""Writing results: the problem export (``.npz``, ``docs/formats.md``) and VTU
files for ParaView (the fabrication drawing is :mod:`.drawing`). Every file is
written atomically (:func:`~tendon_taichi.files.atomic_path`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..body.problem import Problem
from ..files import atomic_path
from ..objective.objective import union_tension

#: arrays every export holds (``docs/formats.md``), in addition to extras
EXPORT_KEYS = ("nodes", "triangles", "fixed", "fiber_nodes_tri", "fiber_nodes_bary", "fibers",
               "a0", "ac", "tau", "x", "target_tri", "target_bary", "target_goal",
               "youngs_modulus", "poisson_ratio", "thickness", "fiber_stiffness", "eps",
               "gravity", "density")


def problem_arrays(problem: Problem, x: np.ndarray, ac: np.ndarray, tau: np.ndarray) -> dict:
    """The export's arrays for positions x (n, 2), contractions ac (f,) m, tensions tau (f,) N."""
    sc, mat, fib = problem.scene, problem.material, problem.fibers
    pairs = fib.pairs
    return {
        "nodes": problem.mesh.nodes, "triangles": problem.mesh.triangles, "fixed": problem.fixed,
        "fiber_nodes": fib.nodes, "fiber_nodes_tri": fib.embedding.tri,
        "fiber_nodes_bary": fib.embedding.bary, "fibers": fib.edges,
        "a0": fib.a0, "ac": np.asarray(ac, dtype=float), "tau": np.asarray(tau, dtype=float),
        "x": np.asarray(x, dtype=float),
        "target_tri": problem.target.tri, "target_bary": problem.target.bary,
        "target_point": np.array([t.point for t in sc.targets]), "target_goal": problem.target_goal,
        "fiber_pairs": pairs.fibers, "fiber_pair_node": pairs.node, "fiber_pair_cos2": pairs.cos2,
        "youngs_modulus": mat.youngs_modulus, "poisson_ratio": mat.poisson_ratio,
        "thickness": mat.thickness, "density": mat.density, "gravity": np.array(mat.gravity),
        "fiber_stiffness": sc.fibers.stiffness, "eps": sc.fibers.eps,
        "max_contraction": sc.fibers.max_contraction, "max_payout": sc.fibers.max_payout,
        "spacing": fib.spacing, "body_size": problem.size, "resolution": problem.level,
        "scene_name": sc.name, "scene_toml": sc.source,
    }


def pose_arrays(problem: Problem, xs: np.ndarray, acs: np.ndarray, taus: np.ndarray) -> dict:
    """The export's per-pose arrays: ``pose_names`` (P,),
    ``target_pose`` (t,) (the pose of each target), ``pose_x`` (P, n, 2) m,
    ``pose_ac`` (P, f) m, ``pose_tau`` (P, f) N and the union tension ``tau_union``
    (f,) N; ``x``, ``ac`` and ``tau`` are those of pose 0."""
    return {"pose_names": np.array(problem.pose_names), "target_pose": problem.target_pose,
            "pose_x": np.asarray(xs, dtype=float), "pose_ac": np.asarray(acs, dtype=float),
            "pose_tau": np.asarray(taus, dtype=float), "tau_union": union_tension(taus)[0]}


def write_export(path: str | Path, problem: Problem, x: np.ndarray, ac: np.ndarray,
                 tau: np.ndarray, **extra) -> Path:
    """Write the problem export to ``path`` (.npz); ``extra`` arrays are added."""
    data = problem_arrays(problem, x, ac, tau)
    data.update(extra)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **data)
    return Path(path)


def write_vtu(path: str | Path, problem: Problem, x: np.ndarray, tau: np.ndarray) -> Path:
    """The deformed mesh (triangles, per-node displacement, clamped flag) and the
    fibers as line cells with their tension, for ParaView or meshio."""
    import meshio

    X = problem.mesh.nodes
    fib = problem.fibers
    c_rest = fib.embedding.positions(problem.mesh.triangles, X)
    c_now = fib.embedding.positions(problem.mesh.triangles, x)
    pts = np.concatenate([x, c_now])
    disp = np.concatenate([x - X, c_now - c_rest])
    n = len(X)
    pad = lambda a: np.concatenate([a, np.zeros((len(a), 1))], axis=1)  # noqa: E731
    mesh = meshio.Mesh(
        pad(pts),
        [("triangle", problem.mesh.triangles), ("line", fib.edges + n)],
        point_data={"displacement": pad(disp),
                    "fixed": np.concatenate([problem.fixed, np.zeros(len(c_now), bool)]).astype(float)},
        cell_data={"tension": [np.zeros(problem.mesh.n_triangles), np.asarray(tau, dtype=float)]},
    )
    with atomic_path(path) as tmp:
        meshio.write(str(tmp), mesh, file_format="vtu")
    return Path(path)


def write_as_built(path: str | Path, problem: Problem, tendon_arrays: dict) -> Path:
    """The as-built robot export (``docs/formats.md``): the body (``nodes``,
    ``triangles``, ``fixed``, material, targets with ``target_pose``), the
    tendons' ``friction`` and ``clearance``, and ``tendon_arrays`` (the tendons'
    embedded waypoints and each pose's equilibrium, contractions and tensions:
    :func:`~tendon_taichi.extract.realizable.as_built_arrays`)."""
    mat, ts = problem.material, problem.scene.tendons
    data = {"nodes": problem.mesh.nodes, "triangles": problem.mesh.triangles, "fixed": problem.fixed,
            "youngs_modulus": mat.youngs_modulus, "poisson_ratio": mat.poisson_ratio, "thickness": mat.thickness,
            "density": mat.density, "gravity": np.array(mat.gravity), "target_tri": problem.target.tri,
            "target_bary": problem.target.bary, "target_goal": problem.target_goal,
            "target_pose": problem.target_pose, "pose_names": np.array(problem.pose_names),
            "body_size": problem.size, "friction": ts.friction, "clearance": ts.clearance,
            "scene_name": problem.scene.name, "resolution": problem.level, **tendon_arrays}
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **data)
    return Path(path)

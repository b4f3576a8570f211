"""How large a problem will be, known before meshing: a scene at a level is
refused when it would not fit in this machine's memory.

The estimates are ratios measured on the built-in scenes at levels 1-3: free
degrees of freedom about 1.8 A / a (body area A, largest triangle area a at
that level; meshing gives 0.94-1.02 of it) and fibers at most 4.3 A / s^2
(fiber spacing s; the lattice has 0.68-1.0 of it). ``docs/performance.md``
gives the process's peak memory per level: about 17 kB per DOF above the
interpreter's 200 MB at level 5.
"""

from __future__ import annotations

import os

from ..errors import SceneError

DOFS_PER_AREA = 1.8  # free DOFs per largest-triangle area
FIBERS_PER_AREA = 4.3  # fibers per spacing^2
#: memory budgeted per DOF (or fiber), twice the measured peak
BYTES_PER_DOF = 32_000
#: the environment variable (or ``--max-dofs``) that overrides the limit
ENV = "TENDON_TAICHI_MAX_DOFS"


def machine_memory() -> int | None:
    """Physical memory in bytes (None where the system does not say)."""
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None


def max_dofs() -> tuple[int | None, str]:
    """The largest problem allowed (DOFs, or fibers) and where the figure comes
    from: ``TENDON_TAICHI_MAX_DOFS`` when set, else half this machine's memory."""
    env = os.environ.get(ENV)
    if env:
        try:
            limit = int(env)
        except ValueError:
            raise SceneError(f"{ENV} must be an integer (got '{env}')") from None
        return limit, f"--max-dofs {limit}"
    mem = machine_memory()
    if mem is None:
        return None, ""
    return int(0.5 * mem / BYTES_PER_DOF), f"half of this machine's {mem / 2**30:.0f} GiB"


def estimate(area: float, max_triangle_area: float, spacing: float) -> tuple[float, float]:
    """(free DOFs, fibers) expected for a body of ``area`` (m^2) meshed with
    triangles up to ``max_triangle_area`` (m^2) and a lattice of ``spacing`` (m)."""
    return DOFS_PER_AREA * area / max_triangle_area, FIBERS_PER_AREA * area / spacing ** 2


def check_size(name: str, level: int, area: float, max_triangle_area: float, spacing: float) -> None:
    """Raise SceneError when the scene at ``level`` would exceed :func:`max_dofs`."""
    limit, source = max_dofs()
    if limit is None:
        return
    dofs, fibers = estimate(area, max_triangle_area, spacing)
    if max(dofs, fibers) > limit:
        raise SceneError(f"{name} at level {level} would have about {dofs:.2g} degrees of freedom and "
                         f"{fibers:.2g} fibers, more than {limit} ({source}); lower the resolution, "
                         f"raise max_triangle_area or spacing, or give --max-dofs")


def check_built(name: str, level: int, dofs: int, fibers: int) -> None:
    """Raise SceneError when a problem already meshed (a recorded run's) exceeds
    :func:`max_dofs`."""
    limit, source = max_dofs()
    if limit is not None and max(dofs, fibers) > limit:
        raise SceneError(f"{name} at level {level} has {dofs} degrees of freedom and {fibers} fibers, "
                         f"more than {limit} ({source})")

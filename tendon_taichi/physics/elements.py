"""The element physics of each dimension, chosen by the mesh's ``dim`` (the body
layer decides it: :mod:`tendon_taichi.body.dimension`). An element set is the
module of Taichi kernels a :class:`~.model.Model` launches on its buffers -
``k_energy``, ``k_gradient``, ``k_hessian``, ``k_hessian_product``,
``k_hessian_entries``, ``k_hessian_sums``, ``k_update_cables``,
``k_cables_to_nodes``, ``k_nodes_to_cables`` and the mixed products - each with
the arguments of :mod:`.forces`, the triangles' set."""

from __future__ import annotations

from types import ModuleType

from ..dimensions import PerDimension
from ..errors import TendonError
from . import forces

#: the element kernels of each dimension, by ``dim``: 2D, Neo-Hookean triangles (forces.py)
ELEMENTS = PerDimension("element kernels", {2: forces})


def element_kernels(dim: int) -> ModuleType:
    """The element kernels of a ``dim``-dimensional mesh (:data:`ELEMENTS`)."""
    return ELEMENTS.of(dim)


def check_elements(dim: int, origin: str | None = None) -> None:
    """One TendonError line, before any work, where no element kernels are registered
    for ``dim`` (3D bodies today: they can be meshed and rigged, not solved); ``origin``
    (a scene file) starts the line."""
    if dim not in ELEMENTS:
        where = f"{origin}: " if origin else ""
        raise TendonError(f"{where}{dim}D bodies can be meshed and rigged, but their physics (element kernels) "
                          "is not built yet")

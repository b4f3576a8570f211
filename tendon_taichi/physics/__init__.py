"""The Taichi model of body + cables: the runtime (:mod:`.runtime`, the one place
Taichi starts), the buffer layout (:mod:`.layout`, :mod:`.buffers`), the energy
densities (:mod:`.energies`), the physics kernels (:mod:`.forces`) and the
:class:`~tendon_taichi.physics.model.Model` that holds one body's buffers."""

from .._lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {".model": ("Model",)})

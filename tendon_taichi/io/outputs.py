"""What a design writes that depends on its body's dimension, chosen by
``problem.dim`` (:mod:`tendon_taichi.body.dimension` decides it): the
fabrication export a designer builds from, and the picture of the design."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..dimensions import PerDimension


@dataclass(frozen=True)
class DesignOutputs:
    """The dimension-dependent files of a design.

    Args:
        dim: the body's dimension.
        fabrication: the fabrication export's file name in a design's folder.
        write_fabrication: ``write(path, problem, tendons, title) -> Path``: the body
            with each route, in mm.
        plot_design: ``plot(path, problem, tendons, realizable, title) -> Path``: the
            routes at rest beside the as-built pose, a PNG.
    """

    dim: int
    fabrication: str
    write_fabrication: Callable[..., Path]
    plot_design: Callable[..., Path]


def _write_svg(path, problem, tendons, title: str = "") -> Path:
    from .drawing import write_svg

    return write_svg(path, problem, tendons, title)


def _plot_design(path, problem, tendons, realizable, title: str) -> Path:
    from .plots import plot_design  # matplotlib: loaded only to draw

    return plot_design(path, problem, tendons, realizable, title)


#: 2D bodies: the SVG drawing (io/drawing.py) and the matplotlib picture (io/plots.py)
PLANE = DesignOutputs(2, "design.svg", _write_svg, _plot_design)

#: the outputs of each dimension, by ``dim``
OUTPUTS = PerDimension("design outputs", {PLANE.dim: PLANE})


def register_outputs(outputs: DesignOutputs) -> DesignOutputs | None:
    """Make ``outputs`` the ones of its ``dim``; returns the ones it replaces, if any."""
    return OUTPUTS.register(outputs.dim, outputs)


def design_outputs(dim: int) -> DesignOutputs:
    """The :class:`DesignOutputs` of a ``dim``-dimensional body."""
    return OUTPUTS.of(dim)

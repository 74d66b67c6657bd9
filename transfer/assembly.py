"""What the kernels are given and how they are run (paper eq. 3-4): which kernel pairs two
meshes, the integration rule, the search distance of surfaces, and the checks on the two
meshes' bounding boxes (no overlap, different units or places). Shared by the serial
operator (:mod:`transfer.operators`) and the distributed one (:mod:`transfer.distributed`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _kernels
from .errors import TransferError
from .grid import StructuredGrid
from .quadrature import check_degree, simplex_rule
from .spaces import FunctionSpace

METHODS = ("l2", "pseudo_l2")

#: a target dof counts as covered when the integral of its basis function over the
#: overlap exceeds this fraction of its integral
COVERED_RTOL = 1e-10

_KIND = {"tetra": _kernels.TET, "hexahedron": _kernels.HEX, "triangle": _kernels.TRI, "quad": _kernels.QUAD}


def _poly_degree(space: FunctionSpace) -> int:
    """Polynomial degree of the basis in physical coordinates (Q1 on a box is
    multilinear: degree tdim; on a general hexahedron it is not a polynomial)."""
    if space.family == "Q1":
        return space.mesh.tdim + (0 if isinstance(space.mesh, StructuredGrid) else 1)
    return space.degree


def _is_affine(space: FunctionSpace) -> bool:
    return space.degree == 0 or space.mesh.cell_type == "tetra"


def default_quadrature_degree(source: FunctionSpace, target: FunctionSpace) -> int:
    """Exact, on affine simplices and boxes, for both products assembled: source
    x target (B) and target x target (D, and the dual basis built from it)."""
    pt = _poly_degree(target)
    return max(1, _poly_degree(source) + pt, 2 * pt)


def _kind(mesh) -> int:
    return _kernels.BOX if isinstance(mesh, StructuredGrid) else _KIND[mesh.cell_type]


def boxes_overlap(a, b, rtol=1e-9) -> bool:
    (alo, ahi), (blo, bhi) = a.bounding_box(), b.bounding_box()
    tol = rtol * max(np.linalg.norm(ahi - alo), np.linalg.norm(bhi - blo))
    return bool(np.all(alo <= bhi + tol) and np.all(blo <= ahi + tol))


#: warn when the bounding-box diameters of source and target differ by more than this
#: factor: mm against m is 1000, while a body immersed in a grid is rarely 10 times smaller
SCALE_FACTOR = 100.0

#: warn when the bounding boxes overlap in less than this fraction of each box: a body
#: inside a larger grid covers little of the grid's box but lies wholly in it, whereas
#: meshes that are misplaced (a shifted origin, another frame) overlap little of both
OVERLAP_FRACTION = 0.1


def _box(mesh) -> str:
    lo, hi = mesh.bounding_box()
    return f"[{', '.join(f'{v:.6g}' for v in lo)}]..[{', '.join(f'{v:.6g}' for v in hi)}]"


def overlap_warnings(smesh, tmesh, proximity: bool = False) -> list[str]:
    """Signs that `smesh` and `tmesh` are in different length units or places.

    With diameters d = |hi - lo| of the bounding boxes: max(d_s, d_t) / min(d_s, d_t)
    > :data:`SCALE_FACTOR`. With the overlap box O of the two boxes: |O| / |box| <
    :data:`OVERLAP_FRACTION` for both boxes, measured per axis (the product of the
    overlapping fractions of the extents, so flat surface boxes count too). Surfaces
    paired by `proximity` (surface to surface) need not overlap: only their size is compared.
    """
    (alo, ahi), (blo, bhi) = smesh.bounding_box(), tmesh.bounding_box()
    ds, dt = np.linalg.norm(ahi - alo), np.linalg.norm(bhi - blo)
    found = []
    factor = max(ds, dt) / min(ds, dt)
    if factor > SCALE_FACTOR:
        found.append(f"{smesh.name} and {tmesh.name} differ in size by a factor {factor:.4g}: bounding boxes "
                     f"{_box(smesh)} (diameter {ds:.4g}) and {_box(tmesh)} (diameter {dt:.4g}); "
                     f"different length units (mm and m differ by 1000)?")
    if not proximity:
        common = np.clip(np.minimum(ahi, bhi) - np.maximum(alo, blo), 0.0, None)
        flat = 1e-9 * max(ds, dt)
        fractions = [np.prod(np.where(hi - lo > flat, common / np.maximum(hi - lo, flat), 1.0))
                     for lo, hi in ((alo, ahi), (blo, bhi))]
        if max(fractions) < OVERLAP_FRACTION:
            found.append(f"{smesh.name} and {tmesh.name} overlap in only {100 * fractions[0]:.2g}% and "
                         f"{100 * fractions[1]:.2g}% of their bounding boxes {_box(smesh)} and {_box(tmesh)}: "
                         f"misplaced, or in different length units?")
    return found


def _mean_edge(mesh) -> float:
    if isinstance(mesh, StructuredGrid):
        return float(np.linalg.norm(mesh.spacing))
    return float(mesh.longest_edges().mean())


def pairing(smesh, tmesh) -> str:
    """How the kernels pair the two meshes: ``"volume"`` (volume-volume, exact
    clipping), ``"trace"`` (a surface target inside a volume source) or ``"surface"``
    (mortar segmentation of two surfaces)."""
    if smesh.tdim < tmesh.tdim:
        raise TransferError(f"{smesh.name} ({smesh.cell_type}) -> {tmesh.name} ({tmesh.cell_type}): a surface "
                            f"field cannot be projected onto a volume; transfer is volume-volume, "
                            f"surface-surface or volume-surface")
    if smesh.tdim == 2:
        return "surface"
    return "trace" if tmesh.tdim == 2 else "volume"


@dataclass(frozen=True)
class Rule:
    """How the kernels integrate: ``degree="exact"`` from the moments of the
    intersection (products of affine bases), else the simplex rule (bary, weights)."""

    degree: int | str
    bary: np.ndarray
    weights: np.ndarray


def integration_rule(source: FunctionSpace, target: FunctionSpace, quadrature_degree: int | None) -> Rule:
    """The rule of :func:`coupling_operator` (see there)."""
    if quadrature_degree is not None:
        check_degree(quadrature_degree)
    smesh, tmesh = source.mesh, target.mesh
    if quadrature_degree is None and smesh.tdim == tmesh.tdim == 3 and _is_affine(source) and _is_affine(target):
        return Rule("exact", np.empty((0, 4)), np.empty(0))
    degree = quadrature_degree or default_quadrature_degree(source, target)
    return Rule(degree, *simplex_rule(tmesh.tdim, degree))


def default_search_distance(tmesh) -> float:
    """Half the mean longest edge of the target surface (mortar pairing distance)."""
    return 0.5 * _mean_edge(tmesh)


def assemble_rows(source: FunctionSpace, target: FunctionSpace, method: str, rule: Rule, *,
                  search_distance: float, max_normal_angle: float, nthreads: int) -> dict:
    """Run the kernel of the pair: the rows of ``B`` and ``D`` of every target cell
    (CSR arrays in the dofs of `source` and `target`), per target cell its overlap
    and measure, the pairs tested and intersected."""
    smesh, tmesh = source.mesh, target.mesh
    kind = pairing(smesh, tmesh)
    dual = method == "pseudo_l2" and target.degree > 0  # the dual of P0/Q0 is itself
    args = (smesh.points, smesh.cells, _kind(smesh), source.degree,
            tmesh.points, tmesh.cells, _kind(tmesh), target.degree,
            rule.bary, rule.weights, dual, method == "pseudo_l2", source.num_dofs, target.num_dofs)
    if kind == "surface":
        return _kernels.assemble_surface(*args, float(search_distance),
                                         float(np.cos(np.radians(max_normal_angle))), nthreads)
    grid = None
    if isinstance(smesh, StructuredGrid):
        grid = (tuple(smesh.origin), tuple(smesh.spacing), tuple(smesh.shape))
    assemble = _kernels.assemble_trace if kind == "trace" else _kernels.assemble_volume
    return assemble(*args, grid, nthreads)


def no_overlap_message(smesh, tmesh) -> str:
    return f"{smesh.name} and {tmesh.name} do not overlap: bounding boxes {_box(smesh)} and {_box(tmesh)}"

"""The fluid-solid interface of a coupled run (paper 2.3, Steps 2, 3 and 6): the
solid as the fluid grid sees it (volume fractions, velocity transfer) and where the
fluid pressure loads the solid (the wetted surface, sampled on the fluid side, or
the volume fallback for solids without boundary triangles), rebuilt from the
deformed solid in every coupling iteration (two-way coupling)."""

from __future__ import annotations

import time

import numpy as np

from transfer import FunctionSpace, Mesh, NoOverlapError, StructuredGrid, Transfer

from coupler.errors import CouplerError

from .centres import centres_inside


class WettedInterface:
    """Steps 2-3 on the wetted boundary: the trace of the fluid's Q0 pressure on the solid's
    interface triangles, sampled on the fluid side.

    The interface vertices are moved along their outward normals (area-weighted means of
    the normals of the interface triangles around them) by half a fluid cell diagonal, so
    the surface lies in fluid cells and not in the penalized cells inside the solid; the
    volume -> surface transfer (pseudo-L2, :mod:`transfer.operators`) gives the pressure
    at its vertices. The interface vector of the fixed point is that pressure (one value
    per interface vertex); the solid gets it at those vertices and zero elsewhere.
    """

    method = "surface trace"

    def __init__(self, S, triangles: np.ndarray, G: StructuredGrid, where: str = "[geometry.fluid]",
                 points=None, depth: float = 1.0, partial: bool = False):
        triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        self.num_points = S.num_points
        self.vertices, local = np.unique(triangles, return_inverse=True)
        self.triangles = local.reshape(-1, 3)
        # the solid's points (the deformed ones, points + displacement, when given)
        points = np.asarray(S.points if points is None else points)[self.vertices]
        normals, per_triangle = np.zeros_like(points), area_normals(points, self.triangles)
        for i in range(3):
            np.add.at(normals, self.triangles[:, i], per_triangle)
        length = np.linalg.norm(normals, axis=1)
        if np.any(length <= 0):
            raise folded_surface(where)
        self.normals = normals / length[:, None]
        self.points = points  # the wall: the interface vertices where the solid is now
        moved, self.offsets = sampling_points(points, self.normals, np.asarray(S.points)[self.vertices], G, depth)
        self.offset = float(self.offsets.max())
        self.surface = Mesh(moved, self.triangles, "triangle", name="interface")
        uncovered, first = len(self.vertices), ""
        try:
            self.transfer = Transfer.assemble(FunctionSpace(G, "Q0"), FunctionSpace(self.surface, "P1"),
                                              "pseudo_l2")
            uncovered = self.transfer.uncovered.size
            if uncovered:
                first = f"; first at {np.array2string(moved[self.transfer.uncovered[0]], precision=6)}"
        except NoOverlapError:
            pass
        check_covered(where, self.offset, uncovered, len(self.vertices), partial, first)
        self.weights = np.asarray(self.transfer.D.sum(axis=1)).ravel()  # lumped surface mass
        self.area = float(self.surface.cell_measures().sum())

    @property
    def size(self) -> int:
        return len(self.vertices)

    num_vertices = size

    @property
    def num_triangles(self) -> int:
        return len(self.triangles)

    def from_fluid(self, pressure) -> np.ndarray:
        """The fluid's cell pressure at the interface vertices."""
        return self.transfer.apply(pressure)

    def to_solid_vertices(self, x) -> np.ndarray:
        """The interface pressure (nv,) or traction (nv, 3) at all solid vertices (zero off the interface)."""
        x = np.asarray(x)
        full = np.zeros((self.num_points,) + x.shape[1:])
        full[self.vertices] = x
        return full

    def describe(self) -> dict:
        return {"method": self.method, "vertices": int(self.size), "triangles": int(self.num_triangles),
                "offset": self.offset, "sampled_area": self.area,
                "pairs_intersected": int(self.transfer.stats["pairs_intersected"])}


def area_normals(points, triangles) -> np.ndarray:
    """Each triangle's normal times its area (outward in boundary_triangles' orientation)."""
    a, b, c = (points[triangles[:, i]] for i in range(3))
    return 0.5 * np.cross(b - a, c - a)


def check_covered(where: str, offset: float, uncovered: int, count: int, partial: bool = False,
                  first: str = "") -> None:
    """CouplerError unless the fluid grid covers the interface sampled `offset` outside the solid:
    `uncovered` of its `count` vertices outside the grid; with `partial` (the deeper velocity
    samples of :mod:`coupler.fsi.viscous`, whose vertices outside the grid read NaN) all of them."""
    if uncovered == count or (uncovered and not partial):
        raise CouplerError(f"{where}: the fluid grid does not cover the interface sampled "
                           f"up to {offset:.3g} m outside the solid ({uncovered} of {count} "
                           f"vertices outside the grid{first}): extend the grid beyond the wetted boundary")


def folded_surface(where: str) -> CouplerError:
    """The error of an interface vertex whose triangles' normals sum to zero."""
    return CouplerError(f"{where}: the interface has a vertex whose triangle normals cancel (a folded surface)")


def sampling_points(points, normals, reference, G: StructuredGrid, depth: float = 1.0):
    """(moved points, offsets): the interface vertices at `points` moved along their unit `normals`
    into the fluid by `depth` times half a cell diagonal (:class:`WettedInterface`); `reference`:
    the undeformed vertices (a vertex on a face of the grid's box stays on it)."""
    # half the cell's extent along the normal, scaled so that it is half the cell diagonal on
    # a cubic grid: 0.5 sqrt(3) |(n_i h_i)|; on anisotropic grids (thin cells across a fracture)
    # a vertical normal moves by 0.87 h_z, not by half the long diagonal
    h = np.asarray(G.spacing, float)
    # (times `depth`: deeper surfaces sample the near-wall velocity profile, coupler/viscous.py)
    offsets = depth * 0.5 * np.sqrt(3.0) * np.linalg.norm(normals * h[None, :], axis=1)
    moved = points + offsets[:, None] * normals
    # a vertex on a face of the grid's box (e.g. a fracture face meeting the inlet) stays on it
    # (a rough face's normal would tilt it out by a few micrometres): clamp the coordinates
    # that lie on the box's faces; any other vertex moved outside is an error of the caller
    lo, hi = np.asarray(G.origin, float), np.asarray(G.origin, float) + h * np.asarray(G.shape)
    tol = 1e-9 * h
    on_face = (np.abs(reference - lo) <= tol) | (np.abs(reference - hi) <= tol)
    # ... and so does an inside vertex moved out along an axis its normal is nearly tangent to
    on_face |= (points >= lo - tol) & (points <= hi + tol) & (np.abs(normals) < 0.5)
    return np.where(on_face, np.clip(moved, lo, hi), moved), offsets


class VolumeInterface:
    """The fallback of Steps 2-3 when the solid gives no interface triangles (stand-in solids
    such as ``spring_solid``): the volume projection Q0 (grid) -> P1 of the pressure onto
    every solid vertex, sampled inside the solid (where a penalized fluid sees no wall)."""

    method = "volume projection"

    def __init__(self, S, G: StructuredGrid, where: str = "[geometry.fluid]"):
        self.transfer = Transfer.assemble(FunctionSpace(G, "Q0"), FunctionSpace(S, "P1"), "pseudo_l2")
        if not np.all(self.transfer.covered):
            raise CouplerError(f"{where}: the fluid grid does not cover the solid "
                               f"({self.transfer.uncovered.size} solid vertices outside it)")
        self.weights = np.asarray(self.transfer.D.diagonal())  # lumped solid mass
        self.size = S.num_points

    def from_fluid(self, pressure) -> np.ndarray:
        return self.transfer.apply(pressure)

    def to_solid_vertices(self, x) -> np.ndarray:
        return np.asarray(x)

    def describe(self) -> dict:
        return {"method": self.method, "vertices": int(self.size),
                "pairs_intersected": int(self.transfer.stats["pairs_intersected"])}


#: depths of the velocity samples beyond the pressure's surface (traction 'full'), in units of its
#: offset: 1.2 offsets = 1.04 cells apart along a grid axis, so consecutive samples lie in different cells
DEPTHS = (2.2, 3.4)


def invalid_deformation(largest: float, reason) -> CouplerError:
    """The error of a deformed solid that is no valid mesh (an inverted tetrahedron: the coupling
    iteration ran away), `largest` the largest displacement."""
    return CouplerError(f"the deformed solid is not a valid mesh (largest displacement {largest:.3g} m): {reason}; "
                        f"the coupling iteration diverges: use [coupling] acceleration = 'iqn-ils' or 'aitken', "
                        f"or a smaller relaxation")


class SolidOnGrid:
    """The solid as the fluid sees it, from the solid's current shape (two-way coupling).

    ``fraction``: the solid volume fraction per grid cell (the Q0 projection of the solid's
    indicator: exact intersection volumes / cell volume; :meth:`centre_fraction` the binary one
    of the cell centres); ``to_fluid``: the P1 -> Q0 transfer
    of the solid velocity; ``interface``: the wetted surface (:class:`WettedInterface`) or the
    fallback (:class:`VolumeInterface`), None for a solid the fluid does not load
    (``wetted=False``); ``current``: the solid's mesh as it is now. :meth:`update` rebuilds them
    from the deformed solid (points + displacement), so the flow sees the aperture the pressure made; it keeps
    the current operators when the displacement is zero (below 1e-12 of the grid spacing) or
    unchanged since the last build, and always with ``deform=False`` or the volume fallback.
    The interface vector keeps its size and vertex order (one value per interface vertex),
    so accelerators see the same unknowns; the residual norm uses the undeformed weights.
    With ``traction="full"`` (the viscous stress too, :mod:`coupler.viscous`) the surfaces
    ``deeper`` sample the fluid further from the wall (``DEPTHS`` times the pressure's offset).
    """

    #: the coupler's ranks the rows are split over (:class:`coupler.fsi.ranks.SolidOnSlabs`); None: one process
    comm = None

    def __init__(self, S, G: StructuredGrid, triangles, where: str, deform: bool = True,
                 traction: str = "pressure", wetted: bool = True):
        self.S, self.G, self.where, self.wetted = S, G, where, wetted
        self.triangles = None if triangles is None or not len(triangles) else np.asarray(triangles)
        self._set_traction(traction, self.triangles is not None)
        self.deform = bool(deform) and self.triangles is not None
        self.num_vertices = len(S.points)
        self._first_build(G)

    def _set_traction(self, traction: str, triangles: bool) -> None:
        """``traction`` and the ``deeper`` surfaces it samples (none yet); 'full' needs the solid's wetted
        `triangles` (CouplerError)."""
        if traction == "full" and not triangles:
            raise CouplerError(f"{self.where}: [coupling] traction = 'full' needs the solid's wetted boundary "
                               f"triangles (the viscous stress acts on a surface); this solid gives none")
        self.traction, self.deeper = traction, []

    def _first_build(self, G: StructuredGrid) -> None:
        """The undeformed build and the bookkeeping of :meth:`update`."""
        self.threshold = 1e-12 * float(np.min(G.spacing))
        self.builds, self.build_seconds, self.skipped = 0, 0.0, 0
        self.max_displacement = 0.0
        self._u = None
        self._build(None)
        self.reference_weights = self.interface.weights if self.wetted else None
        self.builds, self.build_seconds = 0, 0.0  # count the rebuilds only, not the initial build

    def _build(self, u) -> None:
        start = time.perf_counter()
        S = self.S
        if u is not None:
            try:
                S = Mesh(np.asarray(self.S.points) + u, self.S.cells, "tetra", name="deformed solid")
            except Exception as exc:  # an inverted tetrahedron: the coupling iteration ran away
                raise invalid_deformation(float(np.max(np.linalg.norm(u, axis=1))), exc) from exc
        self.to_fluid = None  # the previous shape's operator goes before the new one is made (peak memory)
        to_fluid = Transfer.assemble(FunctionSpace(S, "P1"), FunctionSpace(self.G, "Q0"), "pseudo_l2")
        volumes = np.asarray(to_fluid.D.diagonal())
        self.outside = max(1.0 - float(volumes.sum()) / float(S.cell_measures().sum()), 0.0)
        interface = None  # a solid the fluid does not load has none
        if self.wetted and self.triangles is not None:
            interface = self._wetted(None if u is None else S.points)
        elif self.wetted:
            self._check_inside()
            interface = VolumeInterface(S, self.G, self.where)
        self.to_fluid, self.fraction, self.interface = to_fluid, volumes / self.G.cell_measures(), interface
        self.current, self._centres = S, None
        self.builds += 1
        self.build_seconds += time.perf_counter() - start

    def centre_fraction(self) -> np.ndarray:
        """The binary fraction (``[flow] solid_fraction = "cell_centre"``): 1 in the grid cells whose
        centre lies in the solid as it is now, 0 elsewhere; sampled once per build."""
        if self._centres is None:
            self._centres = self._centres_inside().astype(np.float64)
        return self._centres

    def _centres_inside(self) -> np.ndarray:
        return centres_inside(self.current, self.G)

    def _check_inside(self) -> None:
        """The volume fallback's condition: the whole solid inside the grid (CouplerError if not)."""
        if self.outside > 1e-9:
            raise CouplerError(f"{self.where}: the fluid grid does not cover the solid "
                               f"({self.outside:.3g} of the solid's volume lies outside it)")

    def _wetted(self, points):
        """The wetted surface with the solid's vertices at `points` (None: undeformed) and, with traction
        'full', the ``deeper`` ones."""
        interface = self._surface(points)
        if self.traction == "full":
            self.deeper = [self._deeper(depth, points) for depth in DEPTHS]
        return interface

    def _surface(self, points, depth: float = 1.0, partial: bool = False) -> WettedInterface:
        return WettedInterface(self.S, self.triangles, self.G, self.where, points=points, depth=depth,
                               partial=partial)

    def _deeper(self, depth: float, points):
        """A deeper sampling surface, or None where it leaves the grid entirely (a thin channel)."""
        try:
            return self._surface(points, depth, partial=True)
        except CouplerError:
            return None

    def cell_centres(self) -> np.ndarray:
        """The centres of the grid cells ``fraction`` is given on."""
        return self.G.cell_centers()

    def update(self, u) -> bool:
        """Rebuild from the displacement u (num_vertices, 3) if it changed; True if rebuilt."""
        if not self.deform or u is None:
            return False
        u = np.asarray(u, float).reshape(self.num_vertices, 3)
        size = self._largest(u)
        self.max_displacement = max(self.max_displacement, size)
        if size <= self.threshold:
            u = None
        if (u is None and self._u is None) or (u is not None and self._u is not None and self._equal(u, self._u)):
            self.skipped += 1
            return False
        self._build(u)
        self._u = None if u is None else u.copy()
        return True

    # the reductions of :meth:`update` (over the coupler's ranks in coupler.fsi.ranks.SolidOnSlabs)
    def _largest(self, u: np.ndarray) -> float:
        return float(np.max(np.abs(u))) if u.size else 0.0

    def _equal(self, u: np.ndarray, v: np.ndarray) -> bool:
        return bool(np.array_equal(u, v))

    def describe(self) -> dict:
        return {"deformed": self.deform, "rebuilds": self.builds, "rebuild_seconds": self.build_seconds,
                "seconds_per_rebuild": self.build_seconds / self.builds if self.builds else None,
                "skipped": self.skipped, "solid_volume_outside_grid": self.outside,
                "fluid_cells_with_solid": self._cells_with_solid()}

    def _cells_with_solid(self) -> int:
        return int(np.count_nonzero(self.fraction > 0))

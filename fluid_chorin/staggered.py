"""The staggered (MAC) grid of the Chorin fluid: pressure at cell centres, each velocity
component on the cell faces normal to it, the boundary conditions of the six grid faces,
and the discrete operators of the momentum and continuity equations (paper eq. 12).

Arrays are indexed ``[k, j, i]`` (z, y, x), so ``ravel()`` numbers cells x fastest as
:class:`transfer.StructuredGrid`. Component ``c`` (0 = x, 1 = y, 2 = z) has ``n_c + 1`` faces
along its own axis (array axis ``2 - c``) and ``n`` cells along the two others: ``u`` is
``(nz, ny, nx + 1)``. Its first and last planes along its own axis are the boundary faces,
set by the conditions, never by the momentum equation.

Boundary conditions (:mod:`coupler.protocol.fluid_faces`), per grid face:

* the normal component on the face: 0 on ``wall``, ``slip``, ``symmetry``, ``empty``; the
  given velocity on a ``velocity`` face, masked by the solid: ``u_in (1 - f)``, f the solid
  fraction of the cell behind the face (as the OpenFOAM fluid masks its inlet); on a
  ``pressure`` face it follows the flow (:meth:`Staggered.open_faces`);
* the tangential components through a ghost layer outside the face: ``-inner`` (no slip,
  wall at rest), ``2 g - inner`` (a ``velocity`` face, g its masked tangential value),
  ``inner`` (zero normal gradient: ``slip``, ``symmetry``, ``empty``, ``pressure``);
* the pressure: a ``pressure`` face holds its value half a cell outside the last cell
  centre (Dirichlet); every other face is closed (zero normal flux, Neumann).

A side of a rank's slab (:mod:`fluid_chorin.slabs`) has the kind ``neighbour``: no condition,
its normal faces and its ghost layer hold the neighbour rank's values.

Operators (second order, central): the Laplacian of each component, the convection
``div(u_d u_c)`` in divergence form (Harlow & Welch 1965), the pressure gradient on the
faces and the divergence in the cells.
"""

from __future__ import annotations

import numpy as np

from transfer.grid import BOX_FACES

#: array axis of the x, y and z directions
AXIS = (2, 1, 0)
CLOSED = ("wall", "slip", "symmetry", "empty")


def along(axis: int, s) -> tuple:
    """The index selecting ``s`` along ``axis`` of a 3D array (all along the others)."""
    index = [slice(None)] * 3
    index[axis] = s
    return tuple(index)


def to_faces(cells: np.ndarray, c: int) -> np.ndarray:
    """A cell field on the faces normal to direction ``c``: the mean of the two cells a face
    separates, the adjacent cell's value on the boundary faces."""
    a = AXIS[c]
    padded = np.concatenate([cells[along(a, slice(0, 1))], cells, cells[along(a, slice(-1, None))]], axis=a)
    return 0.5 * (padded[along(a, slice(None, -1))] + padded[along(a, slice(1, None))])


class Staggered:
    """The MAC grid of ``shape`` (nx, ny, nz) cells of ``spacing`` with ``faces`` (face ->
    ``{"kind", "value"}`` from :func:`coupler.protocol.fluid_faces.face_conditions`)."""

    def __init__(self, shape, spacing, faces: dict):
        self.shape = tuple(int(n) for n in shape)
        self.h = np.asarray(spacing, dtype=float).reshape(3)
        self.faces = faces
        self.cells = self.shape[::-1]  # (nz, ny, nx)
        self._buffers: dict[int, np.ndarray] = {}
        #: directions with more than one cell and no 'empty' faces (the others carry no derivative)
        self.active = [not (self.shape[d] == 1 and faces[BOX_FACES[2 * d]]["kind"] == "empty") for d in range(3)]
        self.set_mask(np.ones(self.cells))

    def face_shape(self, c: int) -> tuple:
        s = list(self.cells)
        s[AXIS[c]] += 1
        return tuple(s)

    def zeros(self) -> list[np.ndarray]:
        return [np.zeros(self.face_shape(c)) for c in range(3)]

    def condition(self, d: int, side: int) -> dict:
        return self.faces[BOX_FACES[2 * d + side]]

    @property
    def pressure_faces(self) -> list[tuple[int, int]]:
        """(direction, side) of the fixed-pressure faces."""
        return [(d, s) for d in range(3) for s in (0, 1) if self.condition(d, s)["kind"] == "pressure"]

    # ------------------------------------------------------------------ boundary values
    def _masked(self, d: int, side: int, c: int) -> np.ndarray:
        """``1 - f`` of the cells behind face (d, side), at the positions of component c's
        values on that face (a plane of c's array with axis ``AXIS[d]`` of length 1)."""
        m = self.mask[along(AXIS[d], slice(-1, None) if side else slice(0, 1))]
        return m if c == d else to_faces(m, c)

    def set_normal(self, q: list[np.ndarray]) -> None:
        """The normal components on the closed and velocity faces (in place)."""
        for d in range(3):
            a = AXIS[d]
            for side in (0, 1):
                cond = self.condition(d, side)
                plane = along(a, -1 if side else 0)
                if cond["kind"] in CLOSED:
                    q[d][plane] = 0.0
                elif cond["kind"] == "velocity":
                    q[d][plane] = cond["value"][d] * self._masked(d, side, d)[along(a, 0)]

    def set_mask(self, mask: np.ndarray) -> None:
        """``1 - f`` per cell: the velocity faces' masks and the ghost rules that follow."""
        self.mask = mask
        self._rules = {}
        for c in range(3):
            for d in range(3):
                if d == c:
                    continue
                a = AXIS[d]
                for side in (0, 1):
                    cond = self.condition(d, side)
                    if cond["kind"] == "wall":
                        rule = (-1.0, 0.0)
                    elif cond["kind"] == "velocity":
                        tangential = np.pad(self._masked(d, side, c), 1, mode="edge")[along(a, slice(1, 2))]
                        rule = (-1.0, 2.0 * cond["value"][c] * tangential)
                    else:
                        rule = (1.0, 0.0)
                    self._rules[c, d, side] = rule

    def ghosted(self, c: int, q: np.ndarray) -> np.ndarray:
        """Component c padded by one layer on every side: ghost values outside the grid
        faces tangential to it (the conditions above); along its own axis the padding is
        never read. The array is reused by the next call for the same component."""
        g = self._buffers.get(c)
        if g is None:
            g = self._buffers[c] = np.zeros(tuple(n + 2 for n in q.shape))
        g[1:-1, 1:-1, 1:-1] = q
        for d in range(3):
            if d == c:
                continue
            a = AXIS[d]
            for side in (0, 1):
                sign, offset = self._rules[c, d, side]
                ghost, inner = (slice(-1, None), slice(-2, -1)) if side else (slice(0, 1), slice(1, 2))
                g[along(a, ghost)] = sign * g[along(a, inner)] + offset
        return g

    # ------------------------------------------------------------------ operators
    def interior(self, c: int) -> tuple:
        """The faces of component c that carry a momentum equation (not on the boundary)."""
        return along(AXIS[c], slice(1, -1))

    def momentum_terms(self, q: list[np.ndarray], nu: float) -> list[np.ndarray]:
        """``nu lap(u_c) - div(u u_c)`` on the interior faces of each component."""
        ghosts = [self.ghosted(c, q[c]) for c in range(3)]
        out = []
        for c in range(3):
            A = AXIS[c]
            g = ghosts[c]
            core = [slice(1, -1)] * 3
            core[A] = slice(2, -2)
            centre = g[tuple(core)]
            lap = np.zeros_like(centre)
            for d in range(3):
                if not self.active[d]:
                    continue
                a = AXIS[d]
                lo, hi = list(core), list(core)
                lo[a] = slice(core[a].start - 1, core[a].stop - 1)
                hi[a] = slice(core[a].start + 1, (core[a].stop + 1) or None)
                lap += (g[tuple(lo)] - 2.0 * centre + g[tuple(hi)]) / self.h[d] ** 2
            conv = np.zeros_like(centre)
            if self.active[c]:  # d(u_c u_c)/dx_c from the cell-centre means
                mean = 0.5 * (q[c][along(A, slice(None, -1))] + q[c][along(A, slice(1, None))])
                flux = mean * mean
                conv += (flux[along(A, slice(1, None))] - flux[along(A, slice(None, -1))]) / self.h[c]
            for d in range(3):
                if d == c or not self.active[d]:
                    continue
                a = AXIS[d]
                # u_c at the edges (faces of c x faces of d): mean along d of the ghosted field
                sel = [slice(1, -1)] * 3
                sel[A] = slice(2, -2)
                sel[a] = slice(None)
                gc = g[tuple(sel)]
                uc = 0.5 * (gc[along(a, slice(None, -1))] + gc[along(a, slice(1, None))])
                # u_d at the same edges: mean along c of the interior neighbours
                ud = 0.5 * (q[d][along(A, slice(None, -1))] + q[d][along(A, slice(1, None))])
                flux = uc * ud
                conv += (flux[along(a, slice(1, None))] - flux[along(a, slice(None, -1))]) / self.h[d]
            out.append(nu * lap - conv)
        return out

    def gradient(self, c: int, p: np.ndarray) -> np.ndarray:
        """dp/dx_c on the interior faces of component c."""
        A = AXIS[c]
        return (p[along(A, slice(1, None))] - p[along(A, slice(None, -1))]) / self.h[c]

    def divergence(self, q: list[np.ndarray]) -> np.ndarray:
        out = np.zeros(self.cells)
        for c in range(3):
            A = AXIS[c]
            out += (q[c][along(A, slice(1, None))] - q[c][along(A, slice(None, -1))]) / self.h[c]
        return out

    def boundary_gradient(self, d: int, side: int, p: np.ndarray, value: float) -> np.ndarray:
        """dp/dx_d on pressure face (d, side) holding ``value``, half a cell from the last centre."""
        A = AXIS[d]
        inner = p[along(A, slice(-1, None) if side else slice(0, 1))]
        return (value - inner if side else inner - value) * 2.0 / self.h[d]

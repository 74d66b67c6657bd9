"""Synthetic rough fractures: self-affine surfaces and the two rock blocks around them.

Issue 4 (``cases/fracture_flow``, ``cases/small_fracture``) and paper section 4.2:
water flows through a rough fracture between two rock blocks. This module makes
the geometry, seeded and reproducible.

Surfaces
--------
:func:`rough_surface` synthesizes a self-affine surface spectrally: Fourier
amplitudes ``|k|^-(1+H)`` (power spectrum ``P(k) ~ |k|^-(2+2H)``, ``H`` the
Hurst exponent), random phases, zero mean, rescaled to a given RMS height.
Amplitudes are deterministic (only the phases are random), so the RMS of a
periodic surface is exact and its spectrum is exactly the requested power law.

:func:`fracture_pair` makes the two faces of a fracture (Brown 1995): both
surfaces have the same amplitudes; their phases are *identical* for wavelengths
longer than the ``mismatch_length`` and *independent* for shorter ones, so the
aperture ``upper - lower`` has no power at wavelengths above the mismatch
length. The upper surface is lifted so that the mean aperture is ``aperture``.
Where the aperture would fall below ``min_aperture`` (the surfaces would touch
or interpenetrate), the upper surface is raised to ``lower + min_aperture``
(contact is not modelled here: a later issue); the lift is chosen so that the
mean aperture *after* this clipping is still exactly ``aperture``.

Heights live on a regular node grid: ``h[i, j]`` is the height at
``(x0 + i*Lx/nx, y0 + j*Ly/ny)``, shape ``(nx+1, ny+1)``. Means and integrals
of a height field (:func:`surface_integral`, :func:`surface_mean`) are those of
its piecewise-linear interpolant on the triangulation the block meshes use
(each grid square split along its (i, j)-(i+1, j+1) diagonal), so they match
the mesh volumes exactly.

Blocks
------
:func:`fracture_blocks` builds two tetrahedral meshes: the lower block from
``z = -height`` up to the lower surface, the upper block from the upper surface
up to a flat top. Each is a lattice whose z-coordinates are stretched column by
column (like :func:`transfer.generate.box_tetrahedra` with a vertical map);
every lattice hexahedron is split in the six tets of
:data:`transfer.mesh.HEX_TETS`. Each of those tets has one vertical edge, so its
volume is (projected triangle area) x (vertical edge) / 3 > 0: any column-wise
monotone stretching keeps every tet positively oriented. Boundary triangles are
named ``fracture_lower`` (top of the lower block), ``fracture_upper`` (bottom of
the upper block), ``bottom``, ``top`` and ``xmin, xmax, ymin, ymax`` (the sides),
oriented outward, with the integer tags of :data:`FACE_TAGS`. :meth:`Block.write`
writes a block for meshio and :func:`solid_fenicsx.mesh.read_mesh` (triangle
blocks with ``gmsh:physical`` cell data, names in ``field_data``).
:attr:`FractureBlocks.solid` is both blocks in one mesh (two disjoint pieces),
the solid the coupler works with.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .mesh import Mesh, lattice_tetrahedra

#: integer tag of each named boundary (gmsh physical tags of dimension 2)
FACE_TAGS = {"bottom": 1, "top": 2, "fracture_lower": 3, "fracture_upper": 4,
             "xmin": 5, "xmax": 6, "ymin": 7, "ymax": 8}

#: integer tag of the tetrahedra of each block (gmsh physical tags of dimension 3)
BLOCK_TAGS = {"lower_block": 1, "upper_block": 2}


# -- surfaces -------------------------------------------------------------------
def _grid_shape(shape) -> tuple[int, int]:
    nx, ny = (int(n) for n in shape)
    if nx < 1 or ny < 1:
        raise ValueError(f"surface shape must be two positive cell counts, got {shape}")
    return nx, ny


def _wavenumbers(n, size):
    """|k| (cycles per unit length) on an n[0] x n[1] periodic grid of extent size."""
    kx = np.fft.fftfreq(n[0], d=size[0] / n[0])
    ky = np.fft.fftfreq(n[1], d=size[1] / n[1])
    return np.hypot(kx[:, None], ky[None, :])


def _unit_phases(rng, n) -> np.ndarray:
    """exp(i*phase) with uniformly random phases and Hermitian symmetry (the FFT of white noise, normalized)."""
    f = np.fft.fft2(rng.standard_normal(n))
    mag = np.abs(f)
    return np.where(mag > 0, f / np.where(mag > 0, mag, 1.0), 0.0)


def _amplitudes(k, hurst, cutoff):
    """Fourier amplitudes |k|^-(1+H) (power |k|^-(2+2H)); zero at k = 0 and above 1/cutoff."""
    amp = np.zeros_like(k)
    keep = k > 0
    if cutoff is not None:
        keep &= k <= 1.0 / cutoff
    amp[keep] = k[keep] ** -(1.0 + hurst)
    return amp


def _synthesis(shape, size, hurst, cutoff, seed, periodic, pad, mismatch_length=None):
    """One surface, or a pair with shared phases above the mismatch length; unscaled, on the node grid."""
    nx, ny = _grid_shape(shape)
    if not 0.0 < hurst <= 1.0:
        raise ValueError(f"hurst must be in (0, 1], got {hurst}")
    size = (float(size[0]), float(size[1]))
    if periodic:
        n, ext = (nx, ny), size
    else:  # synthesize on a larger periodic grid and crop: no periodicity, no wrap-around
        n = (int(pad * nx), int(pad * ny))
        ext = (size[0] * n[0] / nx, size[1] * n[1] / ny)
    rng = np.random.default_rng(seed)
    k = _wavenumbers(n, ext)
    amp = _amplitudes(k, hurst, cutoff)
    if not np.any(amp):
        raise ValueError("no Fourier mode left: cutoff shorter than two grid spacings or longer than the domain "
                         f"(cutoff {cutoff}, spacing {size[0] / nx:g} x {size[1] / ny:g})")
    phase = _unit_phases(rng, n)
    fields = [np.fft.ifft2(amp * phase).real]
    if mismatch_length is not None:
        own = _unit_phases(rng, n)
        shared = k < 1.0 / mismatch_length  # wavelength 1/|k| longer than the mismatch length
        fields.append(np.fft.ifft2(amp * np.where(shared, phase, own)).real)
    out = []
    for f in fields:
        if periodic:  # append the wrap-around row and column: node grid (nx+1, ny+1)
            f = np.concatenate([f, f[:1]], axis=0)
            f = np.concatenate([f, f[:, :1]], axis=1)
        else:
            f = f[:nx + 1, :ny + 1]
        out.append(f)
    return out


def _triangles2d(nx, ny) -> np.ndarray:
    """Triangles of the node grid (flat index i*(ny+1)+j), squares split along (i,j)-(i+1,j+1)."""
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    a = (i * (ny + 1) + j).ravel()
    b, c, d = a + (ny + 1), a + (ny + 1) + 1, a + 1  # (i+1,j), (i+1,j+1), (i,j+1)
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def node_weights(shape, size) -> np.ndarray:
    """Quadrature weights (nx+1, ny+1) integrating the piecewise-linear interpolant of a
    node-grid field exactly, on the triangulation the block meshes use (sum = Lx*Ly)."""
    nx, ny = _grid_shape(shape)
    area = size[0] * size[1] / (2 * nx * ny)
    w = np.zeros((nx + 1) * (ny + 1))
    np.add.at(w, _triangles2d(nx, ny).ravel(), area / 3.0)
    return w.reshape(nx + 1, ny + 1)


def surface_integral(heights, size) -> float:
    """Integral over the rectangle of the piecewise-linear interpolant of a node-grid field."""
    h = np.asarray(heights, float)
    return float(np.sum(node_weights((h.shape[0] - 1, h.shape[1] - 1), size) * h))


def surface_mean(heights, size=(1.0, 1.0)) -> float:
    """Area-weighted mean of a node-grid field (:func:`surface_integral` / area)."""
    return surface_integral(heights, size) / (size[0] * size[1])


def rough_surface(shape, size=(1.0, 1.0), hurst=0.8, rms=1.0, seed=None, cutoff=None,
                  periodic=True, pad=2) -> np.ndarray:
    """A self-affine random surface on the node grid, shape (nx+1, ny+1).

    Parameters
    ----------
    shape : (nx, ny) grid cells; size : (Lx, Ly) extent
    hurst : Hurst exponent H in (0, 1]; power spectrum ~ |k|^-(2+2H)
    rms : RMS height after rescaling (area-weighted, about the zero mean)
    seed : seed of numpy's default_rng (same seed, same surface)
    cutoff : shortest wavelength kept (length units); None keeps all up to the grid's Nyquist
    periodic : True: the surface is periodic (last row/column repeat the first; mean and
        RMS exact over the periodic cell). False: synthesized on a grid ``pad`` times larger
        and cropped (no periodicity), then re-centred and rescaled.
    """
    (h,) = _synthesis(shape, size, hurst, cutoff, seed, periodic, pad)
    return _normalize(h, size, rms)[0]


def _normalize(h, size, rms, scale=None):
    h = h - surface_mean(h, size)
    if scale is None:
        current = np.sqrt(surface_mean(h * h, size))
        scale = rms / current if current > 0 else 0.0
    return h * scale, scale


def _lift(diff, weights, aperture, min_aperture):
    """Offset c with mean(max(diff + c, min_aperture)) = aperture (weighted), by bisection."""
    wsum = weights.sum()

    def mean(c):
        return float(np.sum(weights * np.maximum(diff + c, min_aperture)) / wsum)

    lo = aperture - float(np.sum(weights * diff) / wsum)  # clipping only raises the mean: c <= lo
    if mean(lo) <= aperture:
        return lo
    hi, lo = lo, min_aperture - diff.max()  # mean(lo) = min_aperture < aperture
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mean(mid) < aperture else (lo, mid)
        if hi - lo <= 1e-15 * max(1.0, abs(hi)):
            break
    return 0.5 * (lo + hi)


def fracture_pair(shape, size=(1.0, 1.0), aperture=0.1, hurst=0.8, rms=0.1, mismatch_length=None,
                  seed=None, min_aperture=0.0, cutoff=None, periodic=True, pad=2):
    """The two faces of a rough fracture: ``(lower, upper)`` heights on the node grid (nx+1, ny+1).

    Both faces are self-affine (Hurst ``hurst``) with RMS height ``rms`` about their own
    mean; the lower has zero mean. They are identical at wavelengths longer than
    ``mismatch_length`` (default: a quarter of the shorter side) and independent below
    it. The upper face is lifted so that the area-weighted mean aperture
    ``surface_mean(upper - lower)`` equals ``aperture``; where the aperture would be
    below ``min_aperture`` the upper face is raised to ``lower + min_aperture`` (the
    surfaces touch: contact is a later issue), and the lift accounts for that so the
    mean stays ``aperture`` (the upper face's RMS is ``rms`` before this clipping).
    A ``mismatch_length`` longer than the domain gives independent faces; one shorter
    than two grid spacings (or than ``cutoff``) gives identical faces, a uniform aperture.
    ``cutoff``, ``periodic``, ``pad``: as in :func:`rough_surface`; the contact nodes are
    ``np.isclose(upper - lower, min_aperture)``.
    """
    if mismatch_length is None:
        mismatch_length = 0.25 * min(size)
    if mismatch_length <= 0:
        raise ValueError(f"mismatch_length must be positive, got {mismatch_length}")
    if not aperture > min_aperture:
        raise ValueError(f"aperture ({aperture}) must exceed min_aperture ({min_aperture})")
    lower, upper = _synthesis(shape, size, hurst, cutoff, seed, periodic, pad, mismatch_length)
    lower, scale = _normalize(lower, size, rms)
    upper, _ = _normalize(upper, size, rms, scale=scale)  # same factor: long wavelengths stay identical
    diff = upper - lower
    weights = node_weights(shape, size)
    c = _lift(diff, weights, aperture, min_aperture)
    upper = lower + np.maximum(diff + c, min_aperture)
    return lower, upper


def measure_hurst(heights, size=(1.0, 1.0), method="spectrum", fit_range=None) -> float:
    """Hurst exponent of a node-grid surface, from a log-log fit.

    ``spectrum``: radially averaged 2D power spectrum P(k) ~ k^-(2+2H), of one period if the
    surface is periodic (default fit range ``(kmin, kmax)`` = 2/L to a quarter of the Nyquist
    wavenumber, in cycles per length), else of the Hann-windowed surface (16/L to half the
    Nyquist wavenumber: rougher, a single realization of a non-periodic surface).
    ``variogram``: RMS height difference vs lag along x and y, ~ lag^H, over lags
    ``fit_range`` (default: 2 spacings to L/32). Biased low for H near 1 on a finite domain
    (about -0.05 at H = 0.8, -0.08 at H = 0.9 with 256 cells): the missing wavelengths
    above L flatten it.
    """
    h = np.asarray(heights, float)
    if method == "spectrum":
        dx, dy = size[0] / (h.shape[0] - 1), size[1] / (h.shape[1] - 1)
        nyquist = 0.5 / max(dx, dy)
        if np.allclose(h[0], h[-1]) and np.allclose(h[:, 0], h[:, -1]):  # periodic: one period
            f = h[:-1, :-1] - h[:-1, :-1].mean()
            kmin, kmax = fit_range or (2.0 / min(size), 0.25 * nyquist)
        else:  # Hann window against the leakage of the edge jumps; skip its wide main lobe
            f = (h - h.mean()) * np.outer(np.hanning(h.shape[0]), np.hanning(h.shape[1]))
            kmin, kmax = fit_range or (16.0 / min(size), 0.5 * nyquist)
        n = f.shape
        k = _wavenumbers(n, (n[0] * dx, n[1] * dy))
        power = np.abs(np.fft.fft2(f)) ** 2
        edges = np.geomspace(kmin, kmax, 16)
        which = np.digitize(k.ravel(), edges)
        ks, ps = [], []
        for b in range(1, len(edges)):
            sel = which == b
            if sel.any():
                ks.append(k.ravel()[sel].mean())
                ps.append(power.ravel()[sel].mean())
        slope = np.polyfit(np.log(ks), np.log(ps), 1)[0]
        return float(-slope / 2.0 - 1.0)
    if method == "variogram":
        nx, ny = h.shape[0] - 1, h.shape[1] - 1
        dx, dy = size[0] / nx, size[1] / ny
        lo, hi = fit_range or (2 * max(dx, dy), max(min(size) / 32, 6 * max(dx, dy)))
        lags, rms = [], []
        for m in range(1, max(nx, ny)):
            r, d2 = [], []
            if m * dx >= lo and m * dx <= hi and m < nx:
                d2.append(np.mean((h[m:, :] - h[:-m, :]) ** 2)); r.append(m * dx)
            if m * dy >= lo and m * dy <= hi and m < ny:
                d2.append(np.mean((h[:, m:] - h[:, :-m]) ** 2)); r.append(m * dy)
            for rr, dd in zip(r, d2):
                lags.append(rr); rms.append(np.sqrt(dd))
        if len(lags) < 3:
            raise ValueError("too few lags in the fit range")
        return float(np.polyfit(np.log(lags), np.log(rms), 1)[0])
    raise ValueError(f"unknown method {method!r}; use 'spectrum' or 'variogram'")


# -- blocks ---------------------------------------------------------------------
@dataclass(frozen=True)
class Block:
    """A tetrahedral mesh with named boundary triangles.

    Attributes
    ----------
    points : (n, 3); cells : (m, 4) positively oriented tetrahedra (VTK order)
    faces : name -> (k, 3) outward-oriented boundary triangles (indices into points)
    cell_tags : (m,) integer tag of each tet (:data:`BLOCK_TAGS`)
    name : label (used in error messages and files)
    """

    points: np.ndarray
    cells: np.ndarray
    faces: dict
    cell_tags: np.ndarray
    name: str = "block"
    _mesh: list = field(default_factory=list, init=False, repr=False, compare=False)

    @property
    def mesh(self) -> Mesh:
        """The tets as a :class:`transfer.Mesh` (validated: no inverted or degenerate cell)."""
        if not self._mesh:
            self._mesh.append(Mesh(self.points, self.cells, "tetra", name=self.name))
        return self._mesh[0]

    def volume(self) -> float:
        return float(self.mesh.cell_measures().sum())

    def face_mesh(self, name) -> Mesh:
        """One named boundary as a triangle :class:`transfer.Mesh` (same point array)."""
        return Mesh(self.points, self.faces[name], "triangle", name=f"{self.name}:{name}")

    def to_meshio(self):
        """A :class:`meshio.Mesh`: the tets, then one triangle block per named boundary, with
        ``gmsh:physical``/``gmsh:geometrical`` cell data and gmsh ``field_data`` names."""
        import meshio

        names = [n for n in FACE_TAGS if n in self.faces and len(self.faces[n])]
        cells = [("tetra", self.cells)] + [("triangle", self.faces[n]) for n in names]
        tags = [np.asarray(self.cell_tags, np.int32)] + [np.full(len(self.faces[n]), FACE_TAGS[n], np.int32)
                                                         for n in names]
        field_data = {n: np.array([FACE_TAGS[n], 2]) for n in names}
        for n, t in BLOCK_TAGS.items():
            if np.any(self.cell_tags == t):
                field_data[n] = np.array([t, 3])
        return meshio.Mesh(self.points, cells, cell_data={"gmsh:physical": tags, "gmsh:geometrical": tags},
                           field_data=field_data)

    def write(self, path, binary=True) -> Path:
        """Write for meshio and :func:`solid_fenicsx.mesh.read_mesh`: ``.msh`` as gmsh 2.2,
        anything else in the format meshio infers from the suffix (``.vtu``, ``.xdmf``, ...)."""
        import meshio

        path = Path(path)
        m = self.to_meshio()
        if path.suffix == ".msh":
            meshio.write(path, m, file_format="gmsh22", binary=binary)
        elif path.suffix == ".vtu":
            meshio.write(path, m, binary=binary, compression="zlib" if binary else None)
        else:
            meshio.write(path, m)
        return path


@dataclass(frozen=True)
class FractureBlocks:
    """The two rock blocks of a fracture and the surfaces they were built on.

    ``lower``, ``upper``: one :class:`Block` each; ``solid``: both in one mesh (two
    disjoint pieces; the upper block's points follow the lower's); ``heights``: the
    (lower, upper) node-grid surfaces; ``size``, ``origin``: the rectangle in x, y.
    """

    lower: Block
    upper: Block
    solid: Block
    heights: tuple
    size: tuple
    origin: tuple

    @property
    def aperture(self) -> np.ndarray:
        """upper - lower at the grid nodes, (nx+1, ny+1)."""
        return self.heights[1] - self.heights[0]


def _layers(nz, grading, fine_at_top):
    """nz+1 increasing parameters in [0, 1]; cells grow by ``grading`` away from the fine end."""
    if nz < 1:
        raise ValueError(f"need at least one layer per block, got {nz}")
    if grading <= 0:
        raise ValueError(f"grading must be positive, got {grading}")
    steps = float(grading) ** np.arange(nz)  # from the fine end outward
    t = np.concatenate([[0.0], np.cumsum(steps)]) / steps.sum()
    t[-1] = 1.0
    return 1.0 - t[::-1] if fine_at_top else t


def _stretched_lattice(xs, ys, z_of_layer):
    """Points of an (nx+1)(ny+1)(nz+1) lattice, x fastest, z per column; z_of_layer: (nz+1, nx+1, ny+1)."""
    nz = z_of_layer.shape[0] - 1
    k, j, i = np.meshgrid(np.arange(nz + 1), np.arange(len(ys)), np.arange(len(xs)), indexing="ij")
    idx = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)
    points = np.column_stack([xs[idx[:, 0]], ys[idx[:, 1]], z_of_layer[idx[:, 2], idx[:, 0], idx[:, 1]]])
    return points, idx


def _boundary_faces(cells, idx, shape, names):
    """Outward boundary triangles of a positively oriented lattice tet mesh, by lattice face.

    names: the six face names in the order (i=0, i=nx, j=0, j=ny, k=0, k=nz)."""
    # faces opposite vertex 0, 1, 2, 3, ordered so their normal points out of a positive tet
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    # a tet face whose three vertices lie on one face of the lattice (in index space) is on the
    # boundary, in one tet only: no search for unmatched faces is needed
    on_face = np.zeros(len(idx), bool)
    for axis in range(3):
        on_face |= (idx[:, axis] == 0) | (idx[:, axis] == shape[axis])
    tris = cells[:, local].reshape(-1, 3)
    tris = tris[on_face[tris].all(axis=1)]
    lat = idx[tris]  # (f, 3 vertices, 3 axes)
    faces = {}
    for axis in range(3):
        for side, value in enumerate((0, shape[axis])):
            sel = np.all(lat[:, :, axis] == value, axis=1)
            faces[names[2 * axis + side]] = tris[sel]
    return faces


def _block(xs, ys, z_bottom, z_top, nz, grading, fine_at_top, names, tag, name):
    nx, ny = len(xs) - 1, len(ys) - 1
    t = _layers(nz, grading, fine_at_top)
    z = z_bottom[None] + t[:, None, None] * (z_top - z_bottom)[None]
    z[0], z[-1] = z_bottom, z_top  # the faces carry the surface heights exactly
    points, idx = _stretched_lattice(xs, ys, z)
    cells = lattice_tetrahedra((nx, ny, nz))
    faces = _boundary_faces(cells, idx, (nx, ny, nz), names)
    block = Block(points, cells, faces, np.full(len(cells), tag, np.int32), name=name)
    block.mesh  # validate now: raises MeshError on an inverted or degenerate tet
    return block


def _combine(a: Block, b: Block, name="solid") -> Block:
    off = len(a.points)
    faces = {}
    for n in FACE_TAGS:
        parts = [f for f in (a.faces.get(n), None if b.faces.get(n) is None else b.faces[n] + off)
                 if f is not None and len(f)]
        if parts:
            faces[n] = np.concatenate(parts)
    return Block(np.concatenate([a.points, b.points]), np.concatenate([a.cells, b.cells + off]), faces,
                 np.concatenate([a.cell_tags, b.cell_tags]), name=name)


def fracture_blocks(shape, size, height, heights, origin=(0.0, 0.0), top=None, grading=1.0) -> FractureBlocks:
    """Two tetrahedral rock blocks with a rough fracture between them.

    Parameters
    ----------
    shape : (nx, ny, nz) lattice cells: nx x ny in the plane (the surfaces' grid), nz layers per block
    size : (Lx, Ly); origin : (x0, y0) of the rectangle
    height : thickness of each block, measured from the mean plane of its fracture face
    heights : (lower, upper) node-grid surfaces of shape (nx+1, ny+1), e.g. from
        :func:`fracture_pair` (parallel plates: ``(np.zeros(n), np.full(n, w))``)
    top : z of the upper block's top; default ``surface_mean(upper) + height``
    grading : ratio of successive layer thicknesses away from the fracture (1: uniform;
        > 1: thin layers at the fracture)

    The lower block spans ``z = -height`` .. lower(x, y) (faces ``bottom``, ``fracture_lower``),
    the upper block upper(x, y) .. ``top`` (faces ``fracture_upper``, ``top``); both have
    the sides ``xmin, xmax, ymin, ymax``. Raises ValueError if a surface does not lie strictly
    between the bottom and the top, and :class:`transfer.MeshError` on a bad cell.
    """
    nx, ny, nz = (int(n) for n in shape)
    size = (float(size[0]), float(size[1]))
    lower, upper = (np.asarray(h, float) for h in heights)
    for h, which in ((lower, "lower"), (upper, "upper")):
        if h.shape != (nx + 1, ny + 1):
            raise ValueError(f"{which} heights have shape {h.shape}, expected {(nx + 1, ny + 1)} for shape {shape}")
        if not np.all(np.isfinite(h)):
            raise ValueError(f"{which} heights contain NaN or inf")
    if np.any(upper < lower):
        raise ValueError(f"the surfaces cross: upper - lower down to {np.min(upper - lower):.3g}")
    bottom = -float(height)
    top = surface_mean(upper, size) + float(height) if top is None else float(top)
    if not np.all(lower > bottom):
        raise ValueError(f"the lower surface reaches below the bottom z = {bottom:g} (min {lower.min():.3g}); "
                         f"increase height")
    if not np.all(upper < top):
        raise ValueError(f"the upper surface reaches above the top z = {top:g} (max {upper.max():.3g}); "
                         f"increase height")
    xs = origin[0] + np.linspace(0.0, size[0], nx + 1)
    ys = origin[1] + np.linspace(0.0, size[1], ny + 1)
    sides = ("xmin", "xmax", "ymin", "ymax")
    low = _block(xs, ys, np.full_like(lower, bottom), lower, nz, grading, True,
                 sides + ("bottom", "fracture_lower"), BLOCK_TAGS["lower_block"], "lower_block")
    up = _block(xs, ys, upper, np.full_like(upper, top), nz, grading, False,
                sides + ("fracture_upper", "top"), BLOCK_TAGS["upper_block"], "upper_block")
    return FractureBlocks(low, up, _combine(low, up), (lower, upper), size, (float(origin[0]), float(origin[1])))


def write_case_mesh(path, shape, size, height, aperture, min_aperture, rms, hurst, mismatch_length, seed) -> str:
    """Make and write the solid of a fracture case (two blocks around a non-periodic
    matched fracture pair, :func:`fracture_pair` and :func:`fracture_blocks`); return a
    description with the z-range the fluid grid must cover."""
    lower, upper = fracture_pair(shape[:2], size, aperture=aperture, hurst=hurst, rms=rms, seed=seed,
                                 min_aperture=min_aperture, periodic=False, mismatch_length=mismatch_length)
    blocks = fracture_blocks(shape, size, height, (lower, upper))
    written = blocks.solid.write(path)
    w = blocks.aperture
    z = blocks.solid.points[:, 2]
    return "\n".join([
        f"{written}: {len(blocks.solid.points)} points, {len(blocks.solid.cells)} tetrahedra",
        f"aperture mean {surface_mean(w, size) * 1e3:.4f} mm, min {w.min() * 1e3:.4f} mm, max {w.max() * 1e3:.4f} mm",
        f"lower face z in [{lower.min():.6g}, {lower.max():.6g}], upper face z in [{upper.min():.6g}, {upper.max():.6g}]",
        f"top z = {z.max():.6g}, bottom z = {z.min():.6g}"])

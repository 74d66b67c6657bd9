"""Fracture closure under normal stress (paper 4.1, figures 6-10): two rock blocks
around a synthetic self-affine fracture (:mod:`transfer.fracture`), meshed on
different lattices (the lower face ``ratio`` times finer: non-matching faces), closed
by frictionless mortar contact (:class:`Contact`). The specimen is a square box or,
as in the paper, a cylinder: the square lattice mapped onto a disc by the concentric
map (:func:`square_to_disc`) after the rough faces are built, so the face heights stay
the generator's functions of the lattice's (x, y).

Loading: the bottom face rests on a fixed platen and the top face is moved down
by a rigid platen (both platens hold the faces laterally, which removes the rigid
motions a frictionless fracture leaves free). The platen displacement of each
target stress is found by a secant iteration on the mean normal stress on the top
face (its reaction over its area), each solve starting from the last.
Closure = the decrease of the mean aperture (the weighted gap along the slave
normal); the Bandis hyperbolic law sigma = k_ni d / (1 - d / d_max) is fitted to it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from transfer.fracture import FACE_TAGS, fracture_blocks, fracture_pair, surface_mean
from transfer.mesh import Mesh

from .contact import Contact
from .elasticity import Elasticity
from .mesh import from_arrays


@dataclass
class Specimen:
    """The parameters of a fracture closure specimen (SI units)."""

    shape: str = "box"  # or "cylinder" (paper 4.1)
    lattice: tuple = (16, 16, 5)  # lattice of the lower (slave) block: nx, ny, layers per block
    ratio: int = 2  # the upper (master) face's lattice is `ratio` times coarser
    size: float = 0.1  # side of the square, or diameter of the cylinder [m]
    height: float = 0.04  # each block's thickness [m]
    aperture: float = 2.0e-4  # mean initial aperture [m]
    rms: float = 2.0e-4  # RMS roughness of each face [m]
    hurst: float = 0.8
    mismatch_length: float = 0.02  # faces identical at longer wavelengths [m]
    min_aperture: float = 1.0e-6  # where the faces (nearly) touch at the start [m]
    seed: int = 5
    E: float = 1.0e10
    nu: float = 0.33

    def __post_init__(self):
        if self.shape not in SHAPES:
            raise ValueError(f"specimen shape {self.shape!r}: use one of {', '.join(SHAPES)}")

    @property
    def area(self) -> float:
        """Cross-section: size^2, or pi (size / 2)^2 for the cylinder."""
        return self.size ** 2 if self.shape == "box" else np.pi * (self.size / 2) ** 2


SHAPES = ("box", "cylinder")


def square_to_disc(x, y):
    """Shirley's concentric map of the square [-1, 1]^2 onto the unit disc: the square
    of half-side m = max(|x|, |y|) goes to the circle of radius m, uniformly in angle
    along each side. Continuous, piecewise smooth (kinks on the diagonals), with the
    constant Jacobian pi/4 (equal-area: cell volumes scale uniformly). Cells on the
    diagonals get an angle near 180 degrees: where the lattice's diagonal edges cross the
    ray, tets flatten to a quality of about pi / (2 n) at the outline (n cells across)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    wide = np.abs(x) >= np.abs(y)
    radius = np.where(wide, x, y)  # signed: a negative radius turns the angle by pi
    safe = np.where(radius != 0, radius, 1.0)
    angle = np.where(wide, np.pi / 4 * y / safe, np.pi / 2 - np.pi / 4 * x / safe)
    return radius * np.cos(angle), radius * np.sin(angle)


def specimen_mesh(spec: Specimen):
    """The two blocks as one dolfinx mesh with boundaries bottom, top, fracture_lower,
    fracture_upper (and the sides); the lower face is the fine one."""
    nx, ny, nz = spec.lattice
    r = int(spec.ratio)
    if nx % r or ny % r:
        raise ValueError(f"lattice {spec.lattice} is not divisible by ratio {r}")
    size = (spec.size, spec.size)
    lower, upper = fracture_pair((nx, ny), size, aperture=spec.aperture, hurst=spec.hurst, rms=spec.rms,
                                 mismatch_length=spec.mismatch_length, seed=spec.seed,
                                 min_aperture=spec.min_aperture, periodic=False)
    top = surface_mean(upper, size) + spec.height
    fine = fracture_blocks((nx, ny, nz), size, spec.height, (lower, upper), top=top).lower
    coarse = fracture_blocks((nx // r, ny // r, nz), size, spec.height, (lower[::r, ::r], upper[::r, ::r]),
                             top=top).upper
    offset = len(fine.points)
    points = np.concatenate([fine.points, coarse.points])
    cells = np.concatenate([fine.cells, coarse.cells + offset])
    if spec.shape == "cylinder":
        half = spec.size / 2
        x, y = square_to_disc(points[:, 0] / half - 1, points[:, 1] / half - 1)
        points[:, 0], points[:, 1] = half * (1 + x), half * (1 + y)
        Mesh(points, cells, "tetra", name=f"cylindrical specimen {spec.lattice}")  # raises on a bad cell
    tris, tags = [], []
    for block, shift in ((fine, 0), (coarse, offset)):
        for name, faces in block.faces.items():
            tris.append(faces + shift)
            tags.append(np.full(len(faces), FACE_TAGS[name], np.int32))
    solid = from_arrays(points, cells, np.concatenate(tris), np.concatenate(tags), tag_names=FACE_TAGS)
    return solid, (lower, upper)


class ClosureTest:
    """The loading test of a :class:`Specimen`: :meth:`load_to` a mean normal stress."""

    def __init__(self, spec: Specimen, solver: str = "active_set", **options):
        t0 = time.perf_counter()
        self.spec = spec
        self.solid, self.heights = specimen_mesh(spec)
        s = Elasticity(self.solid, E=spec.E, nu=spec.nu)
        s.add_dirichlet("bottom", 0.0)
        self.platen = s.add_dirichlet("top", [0.0, 0.0, 0.0])
        aperture = self.heights[1] - self.heights[0]
        self.contact = Contact(s, "fracture_lower", "fracture_upper", solver=solver,
                               search_distance=2.0 * float(aperture.max()) + spec.rms, **options)
        self.area = spec.area
        m = self.contact.mortar
        self.weights = np.where(m.covered, m.weights, 0.0)
        self.initial_aperture = self._mean(m.gap)
        self.min_gap = max(float(np.nanmin(m.gap)), 0.0)
        self.displacement = 0.0
        self.setup_seconds = time.perf_counter() - t0
        self.solves = []  # figures of every contact solve

    def _mean(self, values) -> float:
        return float(np.sum(self.weights * np.nan_to_num(values)) / np.sum(self.weights))

    def _solve(self, displacement: float):
        self.platen.value[:] = [0.0, 0.0, -displacement]
        state = self.contact.solve()
        state.solution.raise_if_unconverged(f"closure test at platen displacement {displacement:g} m")
        stress = -float(self.contact.reaction("top")[2]) / self.area
        self.solves.append({"displacement": displacement, "stress": stress,
                            "iterations": state.solution.iterations,
                            "krylov_iterations": state.solution.krylov_iterations,
                            "seconds": state.seconds["solve"] + state.seconds["assemble"]})
        return state, stress

    def _check_budget(self, first, max_solves, stress, last):
        if len(self.solves) - first >= max_solves:
            raise RuntimeError(f"platen displacement for {stress:g} Pa not found in {max_solves} solves "
                               f"(last {last:g} Pa)")

    def load_to(self, stress: float, rtol: float = 1e-3, max_solves: int = 20):
        """Move the platen until the mean normal stress on the top is `stress` (secant
        on the platen displacement, from the current one, safeguarded in a bracket); returns
        (state, figures)."""
        first = len(self.solves)
        if not self.solves:  # the unloaded state (faces crossing at the start already push)
            self._solve(0.0)
        d0, s0 = self.solves[-1]["displacement"], self.solves[-1]["stress"]
        # bracket the platen displacement: steps of the elastic column of twice the block
        # height (plus the smallest gap), doubling, towards the target
        step = (stress - s0) * 2 * self.spec.height / self.spec.E + (self.min_gap if s0 <= 0 else 0.0)
        lo, s_lo, hi, s_hi = (d0, s0, None, None) if s0 < stress else (None, None, d0, s0)
        state, s1 = None, s0
        while lo is None or hi is None:
            self._check_budget(first, max_solves, stress, s0)
            d = (lo if hi is None else hi) + step
            state, s1 = self._solve(d)
            if s1 < stress:
                lo, s_lo = d, s1
            else:
                hi, s_hi = d, s1
            step *= 2
        # then regula falsi in the bracket (the stress grows monotonically with the displacement)
        while abs(s1 - stress) > rtol * stress:
            self._check_budget(first, max_solves, stress, s1)
            d = lo + (stress - s_lo) * (hi - lo) / (s_hi - s_lo)
            d = min(max(d, lo + 0.05 * (hi - lo)), hi - 0.05 * (hi - lo))  # stay inside, away from the ends
            state, s1 = self._solve(d)
            if s1 < stress:
                lo, s_lo = d, s1
            else:
                hi, s_hi = d, s1
        d1 = d
        aperture = self._mean(state.gap)
        steps = self.solves[first:]
        return state, {"stress": s1, "platen_displacement": d1, "closure": self.initial_aperture - aperture,
                       "mean_aperture": aperture, "area_fraction": state.area_fraction,
                       "active_nodes": int(state.active.sum()), "max_pressure": float(state.pressure.max()),
                       "contact_force": float(state.force[2]), "solves": len(steps),
                       "iterations": [s["iterations"] for s in steps],
                       "krylov_iterations": [s["krylov_iterations"] for s in steps],
                       "seconds": float(sum(s["seconds"] for s in steps))}


def bandis_fit(stress, closure) -> dict:
    """Fit sigma = k_ni d / (1 - d / d_max) (Bandis et al. 1983), i.e. the line
    sigma / d = k_ni + sigma / d_max; the fitted closure's RMS deviation relative to the largest."""
    stress, closure = np.asarray(stress, float), np.asarray(closure, float)
    slope, k_ni = np.polyfit(stress, stress / closure, 1)
    d_max = 1.0 / slope
    fitted = stress * d_max / (k_ni * d_max + stress)
    return {"k_ni": float(k_ni), "d_max": float(d_max),
            "rms_deviation": float(np.sqrt(np.mean((fitted - closure) ** 2)) / closure.max()),
            "fitted_closure": fitted.tolist()}

"""The periodic elastic half-space, the standard reference of rough contact, for a rough
fracture of the project's generator (issue 30 item 4): bench/halfspace.py closes the same
sampled faces by the stress-controlled platen (paper 4.1) and compares the mean aperture (the
whole plane, contacts as zero) and the contact area fraction at the same mean pressure.

The reference is tamaas's periodic boundary-element contact (Polonsky-Keer-Rey, a bench and
test dependency that scripts/install.sh installs) for the composite problem of two identical
bodies: a rigid surface of heights ``-aperture`` (its peaks where the faces are nearest) on a
flat half-space of modulus E* = E / (2 (1 - nu^2)) (tamaas: ``E = E*``, ``nu = 0``); its gap
field is the aperture, zero on the contacts.
"""

from __future__ import annotations

import numpy as np

from transfer.generators.surfaces import fracture_pair


def fracture_map(cells: int, size: float, aperture: float, rms: float, hurst: float = 0.8,
                 mismatch_length: float | None = None, seed: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """One period of a periodic fracture pair of the project's generator
    (:func:`~transfer.generators.surfaces.fracture_pair`, touching where the aperture would be
    negative): ``(lower, upper)`` heights (cells, cells) [m], indexed [i, j] at (i dx, j dy)."""
    lower, upper = fracture_pair((cells, cells), (size, size), aperture=aperture, hurst=hurst, rms=rms,
                                 mismatch_length=mismatch_length, seed=seed, min_aperture=0.0, periodic=True)
    return lower[:-1, :-1], upper[:-1, :-1]


def effective_modulus(E: float, nu: float) -> float:
    """E* of two identical elastic bodies in contact, E / (2 (1 - nu^2))."""
    return E / (2.0 * (1.0 - nu * nu))


def halfspace(aperture: np.ndarray, size: float, E: float, nu: float, stress: float,
              tolerance: float = 1e-10) -> dict:
    """The periodic half-space's closure of the initial `aperture` (cells, cells) [m] under the
    mean pressure `stress` [Pa]: its aperture field (zero on the contacts), mean aperture,
    contact area fraction and closure (initial minus loaded mean aperture)."""
    import tamaas

    tamaas.set_log_level(tamaas.LogLevel.error)
    model = tamaas.ModelFactory.createModel(tamaas.model_type.basic_2d, [size, size], list(aperture.shape))
    model.E, model.nu = effective_modulus(E, nu), 0.0
    solver = tamaas.PolonskyKeerRey(model, -np.ascontiguousarray(aperture, float), tolerance)
    solver.solve(stress)
    gap = np.array(model["gap"])
    mean = float(gap.mean())
    return {"gap": gap, "mean_aperture": mean, "area_fraction": float(np.mean(model.traction > 0)),
            "closure": float(aperture.mean()) - mean, "stress": float(model.traction.mean())}

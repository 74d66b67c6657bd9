"""The apertures of a fracture in contact: the mechanical aperture e_m (the mean gap between the
faces, contacts counted as zero), the contact area fraction, and the hydraulic aperture e_h of
the cubic law, the parallel-plate gap that passes the same flow (paper 1, 4.2).

The means are sums divided: with `comm` each rank gives its own rows of the slave face (each
node on one rank) and the sums are taken over the ranks before dividing (one allreduce);
``comm=None`` is the serial code."""

from __future__ import annotations

import numpy as np

from coupler.coupling.row_sums import RowSums


def mechanical_aperture(gap: np.ndarray, in_contact: np.ndarray, weights: np.ndarray, comm=None) -> float:
    """e_m: the mean of the gap over the fracture plane, weighted by the nodes' areas (the slave
    face's mortar weights D_kk), contacts counted as zero."""
    open_gap = np.where(in_contact, 0.0, np.maximum(gap, 0.0))
    gaps, area = RowSums(comm).sum(np.array([np.sum(weights * open_gap), np.sum(weights)]))
    return float(gaps / area)


def mean_open_aperture(gap: np.ndarray, in_contact: np.ndarray, weights: np.ndarray, comm=None) -> float:
    """The mean gap over the open part of the fracture plane (0 when it is all in contact)."""
    open_ = ~np.asarray(in_contact, bool)
    gaps, area = RowSums(comm).sum(np.array([np.sum(weights[open_] * np.maximum(gap[open_], 0.0)),
                                             np.sum(weights[open_])]))
    return float(gaps / area) if area > 0 else 0.0


def contact_area_fraction(in_contact: np.ndarray, weights: np.ndarray, comm=None) -> float:
    """The fraction of the fracture plane in contact (by the nodes' areas)."""
    touching, area = RowSums(comm).sum(np.array([np.sum(weights[in_contact]), np.sum(weights)]))
    return float(touching / area)


def hydraulic_aperture(flow_rate: float, viscosity: float, length: float, width: float, pressure_drop: float) -> float:
    """e_h = (12 mu Q L / (W dp))^(1/3): the cubic law Q = W e^3 dp / (12 mu L) solved for e."""
    return float(np.cbrt(12.0 * viscosity * flow_rate * length / (width * pressure_drop)))

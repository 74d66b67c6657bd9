"""The apertures of a fracture in contact: the mechanical aperture e_m (the mean gap between the
faces, contacts counted as zero), the contact area fraction, and the hydraulic aperture e_h of
the cubic law, the parallel-plate gap that passes the same flow (paper 1, 4.2)."""

from __future__ import annotations

import numpy as np


def mechanical_aperture(gap: np.ndarray, in_contact: np.ndarray, weights: np.ndarray) -> float:
    """e_m: the mean of the gap over the fracture plane, weighted by the nodes' areas (the slave
    face's mortar weights D_kk), contacts counted as zero."""
    open_gap = np.where(in_contact, 0.0, np.maximum(gap, 0.0))
    return float(np.sum(weights * open_gap) / np.sum(weights))


def mean_open_aperture(gap: np.ndarray, in_contact: np.ndarray, weights: np.ndarray) -> float:
    """The mean gap over the open part of the fracture plane (0 when it is all in contact)."""
    open_ = ~np.asarray(in_contact, bool)
    area = float(np.sum(weights[open_]))
    return float(np.sum(weights[open_] * np.maximum(gap[open_], 0.0)) / area) if area > 0 else 0.0


def contact_area_fraction(in_contact: np.ndarray, weights: np.ndarray) -> float:
    """The fraction of the fracture plane in contact (by the nodes' areas)."""
    return float(np.sum(weights[in_contact]) / np.sum(weights))


def hydraulic_aperture(flow_rate: float, viscosity: float, length: float, width: float, pressure_drop: float) -> float:
    """e_h = (12 mu Q L / (W dp))^(1/3): the cubic law Q = W e^3 dp / (12 mu L) solved for e."""
    return float(np.cbrt(12.0 * viscosity * flow_rate * length / (width * pressure_drop)))

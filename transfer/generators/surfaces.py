"""Synthetic self-affine rough surfaces and the two faces of a rough fracture.

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
or interpenetrate), the upper surface is raised to ``lower + min_aperture``;
the lift is chosen so that the mean aperture *after* this clipping is still
exactly ``aperture``.

Heights live on a regular node grid: ``h[i, j]`` is the height at
``(x0 + i*Lx/nx, y0 + j*Ly/ny)``, shape ``(nx+1, ny+1)``. Means and integrals
of a height field (:func:`surface_integral`, :func:`surface_mean`) are those of
its piecewise-linear interpolant on the triangulation the block meshes use
(each grid square split along its (i, j)-(i+1, j+1) diagonal), so they match
the mesh volumes exactly (:mod:`transfer.generators.blocks`).
"""

from __future__ import annotations

import numpy as np


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


def node_weights(shape, size, axes=None) -> np.ndarray:
    """Quadrature weights (nx+1, ny+1) integrating the piecewise-linear interpolant of a
    node-grid field exactly, on the triangulation the block meshes use (sum = Lx*Ly); ``axes``:
    the node coordinates (xs, ys) of a grid that is not uniform (its extent is ``size``)."""
    nx, ny = _grid_shape(shape)
    xs, ys = axes if axes is not None else (np.linspace(0.0, size[0], nx + 1), np.linspace(0.0, size[1], ny + 1))
    cell = np.outer(np.diff(xs), np.diff(ys))  # each square in two triangles along (i,j)-(i+1,j+1)
    w = np.zeros((nx + 1, ny + 1))
    w[:-1, :-1] += cell / 3.0  # the diagonal's ends are in both triangles
    w[1:, 1:] += cell / 3.0
    w[1:, :-1] += cell / 6.0
    w[:-1, 1:] += cell / 6.0
    return w


def surface_integral(heights, size, axes=None) -> float:
    """Integral over the rectangle of the piecewise-linear interpolant of a node-grid field
    (``axes``: as in :func:`node_weights`)."""
    h = np.asarray(heights, float)
    return float(np.sum(node_weights((h.shape[0] - 1, h.shape[1] - 1), size, axes) * h))


def surface_mean(heights, size=(1.0, 1.0), axes=None) -> float:
    """Area-weighted mean of a node-grid field (:func:`surface_integral` / area)."""
    return surface_integral(heights, size, axes) / (size[0] * size[1])


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

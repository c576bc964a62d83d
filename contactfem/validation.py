"""Comparisons with closed-form contact solutions (plane-strain Hertz)."""

from __future__ import annotations

import numpy as np

from contactfem.solve import SolveResult


def hertz_comparison(outcome: SolveResult, radius: float, symmetry_axis: float | None = None) -> dict:
    """Relative errors of the contact half-width, peak pressure and pressure profile.

    Plane-strain Hertz for a cylinder of radius R on a rigid plane, with P the total
    contact force per unit thickness from the solve: E* = E/(1 − ν²) (plane strain; E in
    plane stress), a = sqrt(4PR/(πE*)), p0 = 2P/(πa), p(s) = p0 sqrt(1 − s²/a²) with s
    measured along the obstacle from the centre of the contact zone.

    ``symmetry_axis``: the abscissa of a symmetry line through the centre of the zone, when
    the solve modelled half the cylinder (the quarter disk): the zone then runs from the
    axis to one end, and the cylinder's P is twice the solve's contact force.

    The discrete half-width locates each end of the active zone below the mesh size: at a
    contact/separation transition the pressure vanishes like the square root of the
    distance (for any smooth body, not only Hertz's), so p² is extrapolated linearly from
    the last two active nodes to zero, and kept within the last edge of the zone. The
    profile error is the relative L² norm on ΓC of λh − p, λh the method's multiplier.
    """
    law = outcome.problem.law
    # E* = E/(1 − ν²) in plane strain, E in plane stress: both are 4μ(λ+μ)/(λ+2μ) with the
    # plane's own λ (plane stress's 2λμ/(λ+2μ)).
    modulus = 4 * law.mu * (law.lam + law.mu) / (law.lam + 2 * law.mu)
    contact = outcome.solution.contact
    s = outcome.problem.contact.abscissa
    force = float(contact.nodal_force.sum()) * (1 if symmetry_axis is None else 2)
    half_width = np.sqrt(4 * force * radius / (np.pi * modulus))
    peak = 2 * force / (np.pi * half_width)

    active = np.flatnonzero(contact.active)
    first, last = active.min(), active.max()
    pressure_nodes = contact.multiplier
    # The zone as the active nodes show it: ends halfway to the first free node.
    zone_left = 0.5 * (s[first] + s[max(first - 1, 0)])
    zone_right = 0.5 * (s[last] + s[min(last + 1, len(s) - 1)])
    if symmetry_axis is None:
        left = _zone_end(s, pressure_nodes, first, inward=+1)
        right = _zone_end(s, pressure_nodes, last, inward=-1)
        centre = 0.5 * (left + right)
        discrete_half_width = 0.5 * (right - left)
        zone_half_width = 0.5 * (zone_right - zone_left)
    else:
        # The zone's free end is the one away from the axis.
        centre = float(symmetry_axis)
        if abs(s[last] - centre) >= abs(s[first] - centre):
            discrete_half_width = _zone_end(s, pressure_nodes, last, inward=-1) - centre
            zone_half_width = zone_right - centre
        else:
            discrete_half_width = centre - _zone_end(s, pressure_nodes, first, inward=+1)
            zone_half_width = centre - zone_left

    samples = np.linspace(s.min(), s.max(), 40_001)
    pressure_h = np.interp(samples, s, contact.multiplier)
    pressure = peak * np.sqrt(np.clip(1 - ((samples - centre) / half_width) ** 2, 0.0, None))
    # ``load_per_thickness`` is the cylinder's P (twice the solve's force on a half model).
    profile = np.sqrt(np.trapezoid((pressure_h - pressure) ** 2, samples) / np.trapezoid(pressure**2, samples))
    return {
        "load_per_thickness": force,
        "half_width": float(half_width),
        "discrete_half_width": float(discrete_half_width),
        "half_width_error": float((discrete_half_width - half_width) / half_width),
        "zone_half_width": float(zone_half_width),
        "zone_half_width_error": float((zone_half_width - half_width) / half_width),
        "peak_pressure": float(peak),
        "discrete_peak_pressure": float(contact.multiplier.max()),
        "peak_pressure_error": float((contact.multiplier.max() - peak) / peak),
        "profile_error": float(profile),
        "contact_mesh_size": float(np.diff(s[first:last + 1]).max()) if last > first else 0.0,
    }


def _zone_end(s: np.ndarray, pressure: np.ndarray, end: int, inward: int) -> float:
    """Where p² extrapolated from nodes end+inward and end reaches zero, within the free edge beyond."""
    outward = end - inward
    if not (0 <= outward < len(s)):
        return float(s[end])
    inner = end + inward
    p_end, p_inner = pressure[end] ** 2, pressure[inner] ** 2 if 0 <= inner < len(s) else 0.0
    if p_inner <= p_end or p_end <= 0:
        return float(0.5 * (s[end] + s[outward]))
    position = s[end] + p_end * (s[end] - s[inner]) / (p_inner - p_end)
    low, high = sorted((s[end], s[outward]))
    return float(np.clip(position, low, high))

"""EN 14363 test zones from curve radius (docs/design.md §3).

Zone 1: straight track and very large radius curves (R ≥ ``zone1_min_radius_m``, a campaign
setting); zone 2: large radius curves, 600 m < R < ``zone1_min_radius_m``; zone 3: small
radius curves, 400 m ≤ R ≤ 600 m; zone 4: very small radius curves, 250 m ≤ R < 400 m.

References
----------
EN 14363:2005, test zones for on-track tests; Polach & Böttcher 2014 §2 (zone definitions used in
DynoTRAIN).
"""

from __future__ import annotations

import math

from railval.core.errors import InvalidParameter

DEFAULT_ZONE1_MIN_RADIUS_M = 5000.0


def zone_for_radius(radius_m: float | None, zone1_min_radius_m: float = DEFAULT_ZONE1_MIN_RADIUS_M,
                    override: int | None = None) -> int:
    """Return the EN 14363 test zone (1–4) of a section.

    ``radius_m`` in m; ``None``, 0 or ``inf`` mean straight track. ``override`` (1–4) wins.
    Radii below 250 m are outside the EN 14363 zones and raise :class:`InvalidParameter`
    unless overridden.

    Parameters
    ----------
    radius_m : float or None
        Curve radius in m (sign ignored).
    zone1_min_radius_m : float
        Smallest radius in m that still counts as zone 1 (straight or large radius).
    override : int or None
        Zone 1–4 set by hand.

    Returns
    -------
    int
        Test zone 1–4.

    Raises
    ------
    InvalidParameter
        An override outside 1–4 or a radius below 250 m without override.

    Examples
    --------
    >>> zone_for_radius(None)
    1
    """
    if override is not None:
        if override not in (1, 2, 3, 4):
            raise InvalidParameter(f"zone override must be 1, 2, 3 or 4, got {override!r}")
        return int(override)
    if zone1_min_radius_m <= 600:
        raise InvalidParameter(
            f"zone1_min_radius_m must be above 600 m (zone 2 is R > 600 m), got {zone1_min_radius_m}"
        )
    if radius_m is None or radius_m == 0 or math.isinf(radius_m):
        return 1
    r = abs(float(radius_m))
    if r >= zone1_min_radius_m:
        return 1
    if r > 600.0:
        return 2
    if r >= 400.0:
        return 3
    if r >= 250.0:
        return 4
    raise InvalidParameter(
        f"radius_m {radius_m} m is below 250 m, outside the EN 14363 test zones; set a zone override"
    )

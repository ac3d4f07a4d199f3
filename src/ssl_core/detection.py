"""A localized source: the unit of output of :class:`~ssl_core.localizer.Localizer` (array frame)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class DegreesMixin:
    """``azimuth_deg`` / ``elevation_deg`` for a class with ``azimuth`` / ``elevation`` in rad (the user-facing edge)."""

    azimuth: float
    elevation: float

    @property
    def azimuth_deg(self) -> float:
        return float(np.rad2deg(self.azimuth))

    @property
    def elevation_deg(self) -> float:
        return float(np.rad2deg(self.elevation))


@dataclass(frozen=True)
class Detection(DegreesMixin):
    """One localized source, array frame: angles in rad, ``power`` normalised SRP-PHAT (0..1),
    ``level_db`` the delay-and-sum beam's band level toward it (dB re a full-scale sine),
    ``significance`` the detection statistic z (noise standard deviations; see :mod:`ssl_core.localizer`).
    A whole-recording detection (:meth:`Localizer.locate`) carries the means over its windows."""

    azimuth: float
    elevation: float
    direction: np.ndarray
    power: float
    level_db: float
    significance: float = float("nan")

    def to_dict(self) -> dict:
        return {"azimuth_deg": round(self.azimuth_deg, 3), "elevation_deg": round(self.elevation_deg, 3),
                "power": round(self.power, 5), "level_db": round(self.level_db, 2),
                "significance": round(self.significance, 2)}

"""Measurement plans: the in-plane BRDF scan and the glossmeter session.

A :class:`BrdfPlan` is the Wittmann et al. (2021, sec. 2.3) goniometer measurement: the lamp
at a fixed incidence ``theta_i_deg`` (45 deg in the paper) and the detector swept in plane
(0..70 deg), each geometry read ``repeats`` times. Optionally a mirror reference at the
specular geometry (``theta_r = theta_i``) is read first and sets the 100 % level
(the seed reports luminance "in % of a mirror").

A :class:`GlossPlan` is a series of ``count`` glossmeter readings at the ISO 2813
geometries; :func:`gloss_statistics` reduces them to mean and sample standard deviation
per geometry.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from drivers.base import GLOSS_ANGLES_DEG
from goniolab.scan.angle_lists import MAX_ANGLES, PlanError, angle_range, parse_angles

__all__ = [
    "DEFAULT_REPEATS",
    "MAX_ANGLES",
    "MAX_READINGS",
    "MIRROR_INDEX",
    "SAMPLINGS",
    "BrdfPlan",
    "GlossPlan",
    "GlossStats",
    "PlanError",
    "PlanPoint",
    "angle_range",
    "gloss_statistics",
    "parse_angles",
]

#: Longest settling wait before a reading, s: ten minutes is already far beyond any
#: vibration or thermal settling of the arms; ``--dwell 1e300`` was accepted and its ETA
#: printed 300 digits (issue 23, Low).
MAX_DWELL_S = 600.0
#: Most readings (angles x repeats) one plan may hold.
MAX_READINGS = 100_000

#: How a plan's detector angles were chosen (:attr:`BrdfPlan.sampling`).
SAMPLINGS = ("uniform", "adaptive")

#: Readings per geometry when none is asked for: the one default of the CLI (``scan
#: --repeats``), the TUI's setup form, :func:`goniolab.api.run_scan` and the bluesky plan.
DEFAULT_REPEATS = 1

#: Plan index of the mirror reference reading (stored like any point, before index 0).
MIRROR_INDEX = -1


@dataclass(frozen=True, slots=True)
class PlanPoint:
    """One reading of a plan: geometry ``index`` (``MIRROR_INDEX`` for the mirror), ``repeat``."""

    index: int
    theta_i_deg: float
    theta_r_deg: float
    repeat: int

    @property
    def key(self) -> tuple[int, int]:
        """The store's identity of this reading, ``(index, repeat)``."""
        return (self.index, self.repeat)


@dataclass(frozen=True, slots=True)
class BrdfPlan:
    """An in-plane BRDF scan at fixed incidence.

    Attributes
    ----------
    theta_i_deg
        Lamp angle (incidence), degrees.
    theta_r_deg
        Detector angles, signed (> 0 specular side), in scan order.
    repeats
        Readings per geometry (>= 1).
    dwell_s
        Settling time after each move, before the first reading, seconds.
    exposure_us
        Spectro-colorimeter exposure, microseconds (STIL Ruby: 500..250000).
    mirror_reference
        Read a mirror at the specular geometry first; its mean sets the 100 % level.
    sample
        Sample spec (``sample:NAME`` or a height-map path) used for the prediction.
    auto_exposure
        Adapt the exposure to each reading (:mod:`goniolab.scan.exposure`), starting from
        ``exposure_us`` (the default: a spectro that reports its signal level is never left
        saturated or under its noise floor; one that does not keeps ``exposure_us``).
    sampling
        How ``theta_r_deg`` was chosen: ``"uniform"`` (as given) or ``"adaptive"`` (placed
        where the predicted curve bends, :mod:`goniolab.scan.adaptive`); a record only.
    """

    theta_i_deg: float
    theta_r_deg: tuple[float, ...]
    repeats: int = DEFAULT_REPEATS
    dwell_s: float = 0.0
    exposure_us: int = 10000
    mirror_reference: bool = False
    sample: str = ""
    auto_exposure: bool = True
    sampling: str = "uniform"

    def __post_init__(self) -> None:
        if self.sampling not in SAMPLINGS:
            raise PlanError(
                f"sampling must be one of {', '.join(SAMPLINGS)}, got {self.sampling!r}"
            )
        if not math.isfinite(self.theta_i_deg):
            raise PlanError(f"theta_i_deg must be finite, got {self.theta_i_deg}")
        if not self.theta_r_deg:
            raise PlanError("theta_r_deg: the plan has no detector angles")
        if len(set(self.theta_r_deg)) != len(self.theta_r_deg):
            raise PlanError(f"theta_r_deg: repeated detector angles in {list(self.theta_r_deg)}")
        if self.repeats < 1:
            raise PlanError(f"repeats must be >= 1, got {self.repeats}")
        if len(self.theta_r_deg) > MAX_ANGLES:
            raise PlanError(
                f"theta_r_deg: {len(self.theta_r_deg)} angles, more than the {MAX_ANGLES} a plan "
                "may hold"
            )
        if len(self.theta_r_deg) * self.repeats > MAX_READINGS:
            raise PlanError(
                f"{len(self.theta_r_deg)} angles x {self.repeats} repeats = "
                f"{len(self.theta_r_deg) * self.repeats} readings, more than {MAX_READINGS}"
            )
        if not (math.isfinite(self.dwell_s) and 0 <= self.dwell_s <= MAX_DWELL_S):
            raise PlanError(
                f"dwell_s must be in 0..{MAX_DWELL_S:g} s (a settling wait per reading), "
                f"got {self.dwell_s:.6g}"
            )
        if not 500 <= self.exposure_us <= 250000:
            raise PlanError(
                f"exposure_us must be in 500..250000 (STIL Ruby range), got {self.exposure_us}"
            )

    @property
    def n_geometries(self) -> int:
        """Number of detector angles (plan indices 0..n-1)."""
        return len(self.theta_r_deg)

    def points(self) -> list[PlanPoint]:
        """Every reading in measurement order: mirror repeats first (if any), then each
        geometry's repeats in a row (one move per geometry)."""
        pts: list[PlanPoint] = []
        if self.mirror_reference:
            pts.extend(
                PlanPoint(MIRROR_INDEX, self.theta_i_deg, self.theta_i_deg, r)
                for r in range(self.repeats)
            )
        for i, tr in enumerate(self.theta_r_deg):
            pts.extend(PlanPoint(i, self.theta_i_deg, tr, r) for r in range(self.repeats))
        return pts

    def to_dict(self) -> dict[str, Any]:
        """JSON form stored with the run (round-trips through :meth:`from_dict`)."""
        return {
            "kind": "brdf",
            "theta_i_deg": self.theta_i_deg,
            "theta_r_deg": list(self.theta_r_deg),
            "repeats": self.repeats,
            "dwell_s": self.dwell_s,
            "exposure_us": self.exposure_us,
            "mirror_reference": self.mirror_reference,
            "sample": self.sample,
            "auto_exposure": self.auto_exposure,
            "sampling": self.sampling,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> BrdfPlan:
        """Rebuild a plan from :meth:`to_dict` output (a stored run's plan)."""
        try:
            return cls(
                theta_i_deg=float(d["theta_i_deg"]),
                theta_r_deg=parse_angles([float(v) for v in d["theta_r_deg"]]),
                repeats=int(d["repeats"]),
                dwell_s=float(d["dwell_s"]),
                exposure_us=int(d["exposure_us"]),
                mirror_reference=bool(d["mirror_reference"]),
                sample=str(d["sample"]),
                auto_exposure=bool(d.get("auto_exposure", False)),
                sampling=str(d.get("sampling", "uniform")),
            )
        except KeyError as exc:
            raise PlanError(f"stored plan lacks key {exc.args[0]!r}") from exc


@dataclass(frozen=True, slots=True)
class GlossPlan:
    """A glossmeter session: ``count`` readings (0 = until stopped) at ``angles_deg``."""

    count: int = 1
    angles_deg: tuple[int, ...] = GLOSS_ANGLES_DEG
    sample: str = ""

    def __post_init__(self) -> None:
        if self.count < 0:
            raise PlanError(f"count must be >= 0, got {self.count}")
        bad = [a for a in self.angles_deg if a not in GLOSS_ANGLES_DEG]
        if bad or not self.angles_deg:
            raise PlanError(
                f"angles must be a non-empty subset of 20, 60, 85, got {self.angles_deg}"
            )

    def to_dict(self) -> dict[str, Any]:
        """JSON form stored with the run."""
        return {
            "kind": "gloss",
            "count": self.count,
            "angles_deg": list(self.angles_deg),
            "sample": self.sample,
        }


@dataclass(frozen=True, slots=True)
class GlossStats:
    """Mean and sample standard deviation (ddof = 1; 0 for one reading) per geometry."""

    n: dict[int, int] = field(default_factory=dict)
    mean_gu: dict[int, float] = field(default_factory=dict)
    std_gu: dict[int, float] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """JSON form (keys are the geometries as strings)."""
        return {
            str(a): {"n": self.n[a], "mean_gu": self.mean_gu[a], "std_gu": self.std_gu[a]}
            for a in sorted(self.n)
        }


def gloss_statistics(
    readings: Iterable[Mapping[int, float | None]], angles_deg: Sequence[int] = GLOSS_ANGLES_DEG
) -> GlossStats:
    """Mean and sample standard deviation of glossmeter readings per geometry.

    Readings with ``None`` at a geometry (not measured / overflow) are left out of that
    geometry's statistics; geometries with no value at all are omitted.
    """
    values: dict[int, list[float]] = {a: [] for a in angles_deg}
    for r in readings:
        for a in angles_deg:
            v = r.get(a)
            if v is not None:
                values[a].append(float(v))
    stats = GlossStats()
    for a, vs in values.items():
        if not vs:
            continue
        mean = math.fsum(vs) / len(vs)
        std = (
            math.sqrt(math.fsum((v - mean) ** 2 for v in vs) / (len(vs) - 1))
            if len(vs) > 1
            else 0.0
        )
        stats.n[a] = len(vs)
        stats.mean_gu[a] = mean
        stats.std_gu[a] = std
    return stats

"""Certified reference standards as data (``configs/standards.toml``, docs/CALIBRATION.md).

A reference reading is only as good as the number the standard is known to have. Each
standard of the lab (mirror, black glass, white tile, black trap) has a certificate id and
date and a certified spectral reflectance ``R_cert(lambda, theta_i)``, either

* ``model = "table"``: a table of fractions over wavelength (linear interpolation between
  the entries, the end values held beyond them -- a certificate's own convention), or
* ``model = "fresnel"``: a polished dielectric of index ``n``, the unpolarised Fresnel
  reflectance at the reading's incidence (Born & Wolf, *Principles of Optics*, sec. 1.5.2;
  ISO 2813:2014 sec. 5.3: black glass n = 1.567 at 587.6 nm).

A reading of a specimen referenced to a standard read at the same settings is then
absolute (docs/CALIBRATION.md, step 3)::

    R(lambda) = v(lambda) / v_std(lambda) x R_cert(lambda)

The file is found through the lab config's ``[spectro] standards`` (relative to the
config file; default ``standards.toml`` beside it, else the shipped
``configs/standards.toml``: the path used is stored with every run that uses it).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from goniolab.errors import UserError

__all__ = [
    "STANDARD_NAMES",
    "Standard",
    "Standards",
    "StandardsError",
    "load_standards",
    "standards_path",
]

#: The standards a lab file may hold (each optional, at least one).
STANDARD_NAMES: tuple[str, ...] = ("mirror", "black_glass", "white_tile", "black_trap")

_KEYS = {
    "description", "certificate", "certified_on", "model", "wavelength_nm", "reflectance",
    "n", "tolerance",
}  # fmt: skip


class StandardsError(UserError):
    """A standards file that cannot be used; the message names file, key and reason."""

    def __init__(self, path: Path | str, key: str, reason: str) -> None:
        self.path, self.key, self.reason = str(path), key, reason
        where = f"{path}: {key}: " if key else f"{path}: "
        super().__init__(where + reason, exit_code=2)


@dataclass(frozen=True, slots=True)
class Standard:
    """One certified standard; reflectances are fractions (1 = 100 %)."""

    name: str
    certificate: str
    certified_on: str
    model: str
    tolerance: float
    description: str = ""
    wavelength_nm: tuple[float, ...] = ()
    reflectance_table: tuple[float, ...] = ()
    n: float = math.nan
    source: str = ""

    def reflectance(
        self, wavelengths_nm: ArrayLike, theta_i_deg: float = 0.0, *, s_weight: float = 0.5
    ) -> NDArray[np.float64]:
        """Certified reflectance (fraction) at ``wavelengths_nm`` for incidence ``theta_i_deg``,
        as a detector answering ``s_weight`` to s-polarised light reads it.

        A ``fresnel`` standard reflects ``R = w R_s + (1 - w) R_p`` of unpolarised light
        into such a detector (Born & Wolf, *Principles of Optics*, sec. 1.5.2, the
        Fresnel power reflectances; ``w = 0.5`` is the unpolarised ``(R_s + R_p) / 2``
        of the certificate, ISO 2813:2014 sec. 5.3). A ``table`` standard's certificate is
        unpolarised and gives no s and p parts: the table, whatever ``s_weight``
        (:attr:`splits_polarisation`).
        """
        wl = np.asarray(wavelengths_nm, dtype=np.float64)
        if self.model == "fresnel":
            from goniolab.optics.fresnel import fresnel, fresnel_dielectric_sp

            cos_i = math.cos(math.radians(theta_i_deg))
            if s_weight == 0.5:
                r = float(fresnel(cos_i, self.n))
            else:
                r_s, r_p = fresnel_dielectric_sp(cos_i, self.n)
                r = s_weight * float(r_s) + (1.0 - s_weight) * float(r_p)
            return np.full(wl.shape, r)
        return np.asarray(
            np.interp(wl, np.asarray(self.wavelength_nm), np.asarray(self.reflectance_table)),
            dtype=np.float64,
        )

    @property
    def splits_polarisation(self) -> bool:
        """Whether the certificate gives the s and p reflectances apart (a ``fresnel``
        standard: from its index), so that a polarisation-sensitive reading can be held
        to it."""
        return self.model == "fresnel"

    def luminance_pct(self, theta_i_deg: float, weights_y: Sequence[float] | None = None) -> float:
        """Certified value as a luminance in % (Y-weighted mean over 380..780 nm when
        ``weights_y`` on the 10 nm grid is given, else the plain mean)."""
        wl = np.arange(380.0, 781.0, 10.0)
        r = self.reflectance(wl, theta_i_deg)
        if weights_y is None:
            return float(100.0 * r.mean())
        w = np.asarray(weights_y, dtype=np.float64)
        return float(100.0 * np.dot(w, r) / w.sum())

    def cite(self) -> dict[str, Any]:
        """What a run stores about the standard it used (its provenance)."""
        out: dict[str, Any] = {
            "standard": self.name,
            "certificate": self.certificate,
            "certified_on": self.certified_on,
            "model": self.model,
            "file": self.source,
        }
        if self.model == "fresnel":
            out["n"] = self.n
        return out


@dataclass(frozen=True, slots=True)
class Standards:
    """The lab's standards by name (:data:`STANDARD_NAMES`)."""

    path: str
    by_name: Mapping[str, Standard]

    def get(self, name: str) -> Standard:
        """The standard ``name``; a :class:`StandardsError` naming the file if absent."""
        try:
            return self.by_name[name]
        except KeyError:
            raise StandardsError(
                self.path, name, f"no [{name}] standard in the file: add its certificate"
            ) from None


def _number_list(path: Path, key: str, value: object) -> tuple[float, ...]:
    if not isinstance(value, list) or not value:
        raise StandardsError(path, key, "must be a non-empty list of numbers")
    out: list[float] = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise StandardsError(path, key, f"{v!r} is not a finite number")
        out.append(float(v))
    return tuple(out)


def _text(path: Path, key: str, table: Mapping[str, Any], name: str, required: bool) -> str:
    v = table.get(name, "")
    if not isinstance(v, str) or (required and not v.strip()):
        raise StandardsError(path, key + "." + name, "must be a non-empty string")
    return str(v)


def _standard(path: Path, name: str, table: object) -> Standard:
    if not isinstance(table, dict):
        raise StandardsError(path, name, "must be a table")
    unknown = sorted(set(table) - _KEYS)
    if unknown:
        raise StandardsError(path, f"{name}.{unknown[0]}", "unknown key (typo?)")
    cert = _text(path, name, table, "certificate", True)
    date = table.get("certified_on", "")
    if not isinstance(date, str):  # a bare TOML date
        date = str(date)
    if not date.strip():
        raise StandardsError(path, f"{name}.certified_on", "the certificate's date is missing")
    tol = table.get("tolerance", 0.01)
    if isinstance(tol, bool) or not isinstance(tol, int | float) or not 0 < tol < 1:
        raise StandardsError(path, f"{name}.tolerance", f"must be in (0, 1), got {tol!r}")
    model = table.get("model")
    common = {
        "name": name, "certificate": cert, "certified_on": date, "tolerance": float(tol),
        "description": _text(path, name, table, "description", False), "source": str(path),
    }  # fmt: skip
    if model == "fresnel":
        n = table.get("n")
        if isinstance(n, bool) or not isinstance(n, int | float) or not 1.0 < n < 5.0:
            raise StandardsError(
                path, f"{name}.n", f"must be a refractive index in (1, 5), got {n!r}"
            )
        return Standard(model="fresnel", n=float(n), **common)  # type: ignore[arg-type]
    if model == "table":
        wl = _number_list(path, f"{name}.wavelength_nm", table.get("wavelength_nm"))
        r = _number_list(path, f"{name}.reflectance", table.get("reflectance"))
        if len(wl) != len(r):
            raise StandardsError(
                path, f"{name}.reflectance", f"{len(r)} values for {len(wl)} wavelengths"
            )
        if any(b <= a for a, b in itertools.pairwise(wl)):
            raise StandardsError(path, f"{name}.wavelength_nm", "must be strictly ascending")
        if wl[0] > 380.0 or wl[-1] < 780.0:
            raise StandardsError(
                path, f"{name}.wavelength_nm",
                f"covers {wl[0]:g}..{wl[-1]:g} nm; the certificate must cover 380..780 nm",
            )  # fmt: skip
        if any(not 0.0 <= v <= 1.0 for v in r):
            raise StandardsError(path, f"{name}.reflectance", "fractions must be in [0, 1]")
        return Standard(model="table", wavelength_nm=wl, reflectance_table=r, **common)  # type: ignore[arg-type]
    raise StandardsError(path, f"{name}.model", f'must be "table" or "fresnel", got {model!r}')


def load_standards(path: str | Path) -> Standards:
    """Read and validate a standards file.

    Raises
    ------
    StandardsError
        Unreadable file, TOML error, unknown standard or key, missing certificate id or
        date, a table not covering 380..780 nm, a reflectance outside [0, 1].
    """
    from drivers.toml_schema import TomlFileError, read_toml

    p = Path(path)
    try:
        data = read_toml(p, what="standards file")
    except TomlFileError as exc:
        raise StandardsError(p, "", exc.reason) from None
    unknown = sorted(set(data) - set(STANDARD_NAMES))
    if unknown:
        raise StandardsError(
            p, unknown[0], f"unknown standard (one of {', '.join(STANDARD_NAMES)})"
        )
    if not data:
        raise StandardsError(p, "", "no standard in the file")
    return Standards(str(p), {k: _standard(p, k, v) for k, v in data.items()})


def standards_path(config_source: str, name: str = "standards.toml") -> Path:
    """The standards file of a lab config: ``name`` relative to the config's directory when
    it exists there (or is absolute), else the shipped ``configs/<name>``."""
    from goniolab.config import configs_dir

    p = Path(name)
    if p.is_absolute():
        return p
    if config_source:
        local = Path(config_source).resolve().parent / p
        if local.exists():
            return local
    return configs_dir() / p

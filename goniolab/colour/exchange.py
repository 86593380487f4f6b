"""Multi-angle spectra in and out: reflectance factors as a flat table (CSV ``R_400..R_700``).

A paint lab's instruments (BYK-mac i, X-Rite MA-T12/MA98) export one row per measurement
geometry with the reflectance per wavelength in columns; goniolab writes and reads the same
shape so that a measured panel can be compared with a prediction and a prediction opened in
the lab's colour software::

    # goniolab multi-angle spectra: reflectance factor (1 = perfect reflecting diffuser)
    source,theta_i_deg,theta_r_deg,aspecular_deg,repeat,R_400,R_410,...,R_700
    measured,45,30,15,0,0.5121,0.5133,...

Angles follow ASTM E2194 (aspecular = theta_i - theta_r, :mod:`goniolab.colour.multiangle`).
The reader takes ``aspecular_deg`` (with ``theta_i_deg``, default 45) or ``theta_r_deg``; the
spectral columns are ``R_<nm>`` (also ``R<nm>``, ``<nm>`` or ``<nm>nm``); values are factors,
or percent with ``unit="percent"`` (the caller says which: no guessing). Rows of the same
geometry are repeats and are averaged *as spectra* (the colour of the mean spectrum, not the
mean of colours). The grid is validated by :func:`goniolab.colour.spectra.check_spectrum`
(evenly spaced, inside 360-830 nm, covering 400-700 nm).

CxF3 files (ISO 17972-1) give the same table through
:func:`goniolab.colour.cxf_files.read_spectra_cxf` (the optional ``colour-cxf`` package).
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from goniolab.colour.multiangle import E2194_INCIDENCE_DEG, aspecular_deg, theta_r_for_aspecular
from goniolab.colour.spectra import ColourError, check_spectrum

__all__ = [
    "CSV_HEADER_NOTE",
    "MultiAngleSpectra",
    "read_spectra_csv",
    "spectra_csv",
    "spectral_column",
    "union_table",
]

FloatArray = NDArray[np.float64]

#: The first line of an exported table; a run on the ``mirror`` scale says otherwise.
MIRROR_NOTE = (
    "# goniolab multi-angle spectra: fraction of the mirror reference ([colour] scale = "
    "mirror), not reflectance factors; aspecular_deg = theta_i_deg - theta_r_deg (ASTM E2194)"
)
CSV_HEADER_NOTE = (
    "# goniolab multi-angle spectra: reflectance factor (1 = perfect reflecting diffuser); "
    "aspecular_deg = theta_i_deg - theta_r_deg (ASTM E2194)"
)
_SPECTRAL = re.compile(r"^\s*r?_?\s*(\d+(?:\.\d+)?)\s*(?:nm)?\s*$", re.IGNORECASE)


def spectral_column(wavelength_nm: float) -> str:
    """``R_400`` for 400 nm (``R_402.5`` for a fractional wavelength)."""
    return f"R_{wavelength_nm:g}"


@dataclass(frozen=True, slots=True)
class MultiAngleSpectra:
    """Reflectance factors ``(n, N)`` per geometry on one wavelength grid.

    ``source`` per row is ``"measured"``, ``"predicted"`` or the file's own label;
    ``repeat`` numbers repeats of a geometry (0 when there are none); ``notes`` are what the
    reader says about how it read the file (a CxF3 single-angle geometry read as one angle).
    """

    wavelengths_nm: FloatArray
    theta_i_deg: FloatArray
    theta_r_deg: FloatArray
    factors: FloatArray
    source: tuple[str, ...]
    repeat: tuple[int, ...]
    notes: tuple[str, ...] = ()

    @property
    def aspecular_deg(self) -> FloatArray:
        """ASTM E2194 aspecular angle per row, ``theta_i - theta_r``."""
        out: FloatArray = self.theta_i_deg - self.theta_r_deg
        return out

    def select(self, source: str) -> MultiAngleSpectra:
        """The rows of one ``source`` (all rows when the table has no such label)."""
        idx = [k for k, s in enumerate(self.source) if s == source]
        if not idx:
            return self
        return MultiAngleSpectra(
            self.wavelengths_nm,
            self.theta_i_deg[idx],
            self.theta_r_deg[idx],
            self.factors[idx],
            tuple(self.source[k] for k in idx),
            tuple(self.repeat[k] for k in idx),
            self.notes,
        )

    def averaged(self) -> MultiAngleSpectra:
        """One row per (source, theta_i, theta_r): the mean spectrum of its repeats."""
        keys: dict[tuple[str, float, float], list[int]] = {}
        for k, (s, ti, tr) in enumerate(zip(self.source, self.theta_i_deg, self.theta_r_deg,
                                            strict=True)):  # fmt: skip
            keys.setdefault((s, round(float(ti), 6), round(float(tr), 6)), []).append(k)
        rows = list(keys.items())
        return MultiAngleSpectra(
            self.wavelengths_nm,
            np.array([k[1] for k, _ in rows]),
            np.array([k[2] for k, _ in rows]),
            np.array([self.factors[idx].mean(axis=0) for _, idx in rows]),
            tuple(k[0] for k, _ in rows),
            tuple(0 for _ in rows),
            self.notes,
        )


def union_table(spectra: Sequence[MultiAngleSpectra]) -> MultiAngleSpectra:
    """Several tables on one grid (the union of theirs; NaN where a table has no value)."""
    wl = np.unique(np.concatenate([sp.wavelengths_nm for sp in spectra]))
    rows: list[FloatArray] = []
    for sp in spectra:
        block = np.full((sp.factors.shape[0], wl.size), np.nan)
        block[:, np.searchsorted(wl, sp.wavelengths_nm)] = sp.factors
        rows.append(block)
    return MultiAngleSpectra(
        wl,
        np.concatenate([sp.theta_i_deg for sp in spectra]),
        np.concatenate([sp.theta_r_deg for sp in spectra]),
        np.concatenate(rows),
        tuple(x for sp in spectra for x in sp.source),
        tuple(x for sp in spectra for x in sp.repeat),
    )


def spectra_csv(
    spectra: Sequence[MultiAngleSpectra], *, digits: int = 6, note: str = CSV_HEADER_NOTE
) -> str:
    """The CSV text of one or more tables, on the union of their grids (an empty cell where
    a table has no value: a 400-700 nm measurement beside a 380-780 nm prediction)."""
    sp = union_table(spectra)
    buf = io.StringIO()
    buf.write(note + "\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(
        ["source", "theta_i_deg", "theta_r_deg", "aspecular_deg", "repeat"]
        + [spectral_column(x) for x in sp.wavelengths_nm]
    )
    for k in range(sp.factors.shape[0]):
        w.writerow(
            [sp.source[k], f"{sp.theta_i_deg[k]:g}", f"{sp.theta_r_deg[k]:g}",
             f"{aspecular_deg(float(sp.theta_r_deg[k]), float(sp.theta_i_deg[k])):g}",
             sp.repeat[k]]
            + ["" if not math.isfinite(v) else f"{v:.{digits}g}" for v in sp.factors[k]]
        )  # fmt: skip
    return buf.getvalue()


def _float(text: str, where: str, decimal_comma: bool = False) -> float:
    try:
        v = float(text.replace(",", ".") if decimal_comma else text)
    except ValueError:
        raise ColourError(f"{where}: {text!r} is not a number") from None
    if not math.isfinite(v):
        raise ColourError(f"{where}: {text!r} is not finite")
    return v


def read_spectra_csv(
    text: str,
    *,
    where: str = "spectra",
    unit: Literal["factor", "percent"] = "factor",
    theta_i_deg: float = E2194_INCIDENCE_DEG,
) -> MultiAngleSpectra:
    """Parse a multi-angle spectra CSV (the first header block; ``#`` lines are comments).

    What spreadsheet programs write is read as such: a UTF-8 byte-order mark is skipped, and
    a header with no comma but semicolons (or tabs) sets the separator, with decimal commas
    in the cells (``0,45``: the CSV of a German or French Excel).

    Raises
    ------
    ColourError
        ``where: line N: reason`` -- no spectral columns, no angle column, a cell that is
        not a number, a spectrum :func:`check_spectrum` refuses.
    """
    text = text.removeprefix("\ufeff")  # Excel's "CSV UTF-8"
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise ColourError(f"{where}: no rows")
    sep = next((d for d in (",", ";", "\t") if d in lines[0]), ",")
    comma = sep != ","  # then a comma in a cell is a decimal comma
    rows = list(csv.reader(lines, delimiter=sep))
    header = [h.strip() for h in rows[0]]
    lower = [h.lower() for h in header]
    spectral: list[tuple[int, float]] = []
    for k, h in enumerate(header):
        m = _SPECTRAL.match(h)
        if m and lower[k] not in ("repeat",):
            spectral.append((k, float(m.group(1))))
    if len(spectral) < 3:
        raise ColourError(
            f"{where}: line 1: no spectral columns (name them R_400, R_410, ... in nm)"
        )
    wl = np.array([w for _, w in spectral])
    col = {name: lower.index(name) for name in lower if name in (
        "source", "theta_i_deg", "theta_r_deg", "aspecular_deg", "repeat")}  # fmt: skip
    if "theta_r_deg" not in col and "aspecular_deg" not in col:
        raise ColourError(f"{where}: line 1: needs an aspecular_deg or theta_r_deg column")
    scale = 0.01 if unit == "percent" else 1.0
    ti_l: list[float] = []
    tr_l: list[float] = []
    fac: list[FloatArray] = []
    src: list[str] = []
    rep: list[int] = []
    for n, row in enumerate(rows[1:], start=2):
        w = f"{where}: line {n}"
        if len(row) != len(header):
            raise ColourError(f"{w}: {len(row)} cells for {len(header)} columns")
        if row == header:  # a second block's header: only the first block is read
            break
        cell = {name: _float(row[k], f"{w}, {header[k]}", comma) for name, k in col.items()
                if name != "source"}  # fmt: skip
        ti = cell["theta_i_deg"] if "theta_i_deg" in col else float(theta_i_deg)
        if "theta_r_deg" in col:
            tr = cell["theta_r_deg"]
        else:
            tr = theta_r_for_aspecular(cell["aspecular_deg"], ti)
        if not (abs(ti) < 90.0 and abs(tr) < 90.0):
            raise ColourError(f"{w}: geometry theta_i {ti:g}, theta_r {tr:g} is below the horizon")
        values = np.array(
            [np.nan if not row[k].strip() else _float(row[k], f"{w}, {header[k]}", comma)
             for k, _ in spectral]
        ) * scale  # fmt: skip
        ti_l.append(ti)
        tr_l.append(tr)
        fac.append(values)
        src.append(row[col["source"]].strip() if "source" in col else "measured")
        rep.append(int(cell["repeat"]) if "repeat" in col else 0)
    if not fac:
        raise ColourError(f"{where}: a header but no spectra")
    table = np.array(fac)
    keep = np.all(np.isfinite(table), axis=0)  # the wavelengths every row has
    if not keep.any():
        raise ColourError(f"{where}: no wavelength has a value in every row")
    wl_k = wl[keep]
    for n, v in enumerate(table[:, keep], start=2):
        check_spectrum(wl_k, v, what=f"{where}: line {n}")
    return MultiAngleSpectra(
        wl_k, np.array(ti_l), np.array(tr_l), table[:, keep], tuple(src), tuple(rep)
    )

"""Refractive index against wavelength: constant, Cauchy, Sellmeier, or a tabulated n, k.

The clear coat's index n(lambda) sets the Fresnel reflection of the coat surface at every
wavelength (PHYSICS.md, "Colour and the paint layer"; Durikovic et al. 2007, sec. 5.1: resin
indices 1.4-1.6); metal flakes need a complex n + ik (Mihalik & Durikovic eq. 10).

- Cauchy: ``n = A + B / lambda^2 + C / lambda^4`` (lambda in um).
- Sellmeier: ``n^2 = 1 + sum_j B_j lambda^2 / (lambda^2 - C_j)`` (lambda in um, C_j in um^2).
- Table: n and k at listed wavelengths, linearly interpolated; outside the table the end
  values are held (and :meth:`Dispersion.check_covers` names a grid that leaves it).

Every form is a frozen dataclass with :meth:`index` returning complex n + ik per wavelength.

References
----------
.. [1] M. Born, E. Wolf, Principles of Optics, 7th ed., sec. 2.3.4 (Cauchy, Sellmeier).
.. [2] SCHOTT optical glass data sheet N-BK7: B = (1.03961212, 0.231792344, 1.01046945),
   C = (0.00600069867, 0.0200179144, 103.560653) um^2; n_d(587.56 nm) = 1.5168.
.. [3] A. D. Rakic et al., Appl. Opt. 37 (1998) 5271: optical constants of aluminium.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "ALUMINIUM",
    "Cauchy",
    "Constant",
    "Dispersion",
    "DispersionError",
    "Sellmeier",
    "Tabulated",
    "dispersion_from_dict",
    "parse_nk_table",
]

ComplexArray = NDArray[np.complex128]


class DispersionError(ValueError):
    """A dispersion formula or table is unusable (the message names the key or line)."""


def _um(wavelength_nm: ArrayLike) -> NDArray[np.float64]:
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    if np.any(~np.isfinite(wl)) or np.any(wl <= 0):
        raise DispersionError("wavelengths must be finite and positive")
    out: NDArray[np.float64] = wl * 1e-3
    return out


class Dispersion:
    """Base: a refractive index per wavelength."""

    def index(self, wavelength_nm: ArrayLike) -> ComplexArray:
        """Complex index ``n + ik`` at each wavelength (nm)."""
        raise NotImplementedError

    def n_range(self, wavelength_nm: ArrayLike) -> tuple[float, float]:
        """Smallest and largest real part over the given wavelengths."""
        n = self.index(wavelength_nm).real
        return float(n.min()), float(n.max())

    def is_dielectric(self, wavelength_nm: ArrayLike) -> bool:
        """True when k = 0 at every wavelength given."""
        return bool(np.all(self.index(wavelength_nm).imag == 0.0))

    def check_covers(self, wavelength_nm: ArrayLike) -> None:
        """Raise :class:`DispersionError` when the grid leaves the formula's valid range."""

    def describe(self) -> dict[str, Any]:
        """Parameters as stored with a run."""
        raise NotImplementedError

    def _check(self, n: ComplexArray) -> ComplexArray:
        if np.any(~np.isfinite(n)) or np.any(n.real <= 0) or np.any(n.imag < 0):
            raise DispersionError(
                f"{type(self).__name__} gives an index with n <= 0, k < 0 or not finite"
            )
        return n


@dataclass(frozen=True, slots=True)
class Constant(Dispersion):
    """The same index at every wavelength (the grey model of the luminance prediction)."""

    n: complex = 1.55

    def index(self, wavelength_nm: ArrayLike) -> ComplexArray:
        wl = np.asarray(wavelength_nm, dtype=np.float64)
        return self._check(np.full(wl.shape, complex(self.n), dtype=np.complex128))

    def describe(self) -> dict[str, Any]:
        n = complex(self.n)
        return {"kind": "constant", "n": n.real, "k": n.imag}


@dataclass(frozen=True, slots=True)
class Cauchy(Dispersion):
    """``n = A + B/lambda^2 + C/lambda^4`` with lambda in um (Born & Wolf 2.3.4)."""

    A: float
    B: float = 0.0
    C: float = 0.0

    def index(self, wavelength_nm: ArrayLike) -> ComplexArray:
        lam = _um(wavelength_nm)
        n = self.A + self.B / lam**2 + self.C / lam**4
        return self._check(n.astype(np.complex128))

    def describe(self) -> dict[str, Any]:
        return {"kind": "cauchy", "A": self.A, "B": self.B, "C": self.C}


@dataclass(frozen=True, slots=True)
class Sellmeier(Dispersion):
    """``n^2 = 1 + sum B_j lambda^2/(lambda^2 - C_j)``, lambda in um, C_j in um^2."""

    B: tuple[float, ...]
    C: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.B) != len(self.C) or not self.B:
            raise DispersionError("sellmeier: B and C need the same number (>= 1) of terms")

    def index(self, wavelength_nm: ArrayLike) -> ComplexArray:
        lam2 = _um(wavelength_nm) ** 2
        n2 = np.ones_like(lam2)
        for b, c in zip(self.B, self.C, strict=True):
            n2 = n2 + b * lam2 / (lam2 - c)
        if np.any(n2 <= 0):
            raise DispersionError("sellmeier: n^2 <= 0 at a wavelength (near a resonance C_j)")
        return self._check(np.sqrt(n2).astype(np.complex128))

    def describe(self) -> dict[str, Any]:
        return {"kind": "sellmeier", "B": list(self.B), "C": list(self.C)}


@dataclass(frozen=True, slots=True)
class Tabulated(Dispersion):
    """n and k at listed wavelengths, interpolated linearly (end values held outside)."""

    wavelengths_nm: tuple[float, ...]
    n: tuple[float, ...]
    k: tuple[float, ...] = field(default=())
    source: str = ""

    def __post_init__(self) -> None:
        wl = np.asarray(self.wavelengths_nm, dtype=float)
        where = self.source or "n,k table"
        if wl.size < 2:
            raise DispersionError(f"{where}: needs at least 2 wavelengths")
        if len(self.n) != wl.size or (self.k and len(self.k) != wl.size):
            raise DispersionError(f"{where}: n and k need one value per wavelength")
        if np.any(np.diff(wl) <= 0):
            raise DispersionError(f"{where}: wavelengths must be ascending")
        vals = np.asarray(self.n + tuple(self.k), dtype=float)
        if np.any(~np.isfinite(vals)) or np.any(np.asarray(self.n) <= 0):
            raise DispersionError(f"{where}: n must be positive and finite")
        if self.k and np.any(np.asarray(self.k) < 0):
            raise DispersionError(f"{where}: k must be >= 0")

    def index(self, wavelength_nm: ArrayLike) -> ComplexArray:
        wl = np.asarray(wavelength_nm, dtype=np.float64)
        n = np.interp(wl, self.wavelengths_nm, self.n)
        k = np.interp(wl, self.wavelengths_nm, self.k) if self.k else np.zeros_like(n)
        return self._check((n + 1j * k).astype(np.complex128))

    def check_covers(self, wavelength_nm: ArrayLike) -> None:
        wl = np.asarray(wavelength_nm, dtype=np.float64)
        lo, hi = self.wavelengths_nm[0], self.wavelengths_nm[-1]
        if wl.min() < lo - 1e-9 or wl.max() > hi + 1e-9:
            raise DispersionError(
                f"{self.source or 'n,k table'}: covers {lo:g}-{hi:g} nm, "
                f"the grid needs {wl.min():g}-{wl.max():g} nm"
            )

    def describe(self) -> dict[str, Any]:
        return {
            "kind": "table",
            "source": self.source,
            "wavelengths_nm": list(self.wavelengths_nm),
            "n": list(self.n),
            "k": list(self.k),
        }


def parse_nk_table(text: str, *, source: str = "n,k table") -> Tabulated:
    """Parse a text table: one ``wavelength_nm n [k]`` row per line (comma, tab or space
    separated; ``#`` comments and a header line of words are skipped).

    Raises
    ------
    DispersionError
        Naming the source and the line number of a malformed row.
    """
    rows: list[tuple[float, float, float]] = []
    has_k = False
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.replace(",", " ").replace(";", " ").split()
        try:
            nums = [float(p) for p in parts]
        except ValueError:
            if not rows:  # a header line
                continue
            raise DispersionError(
                f"{source}: line {lineno}: not numbers: {raw.strip()!r}"
            ) from None
        if len(nums) not in (2, 3):
            raise DispersionError(
                f"{source}: line {lineno}: expected 'wavelength_nm n [k]', got {len(nums)} values"
            )
        has_k = has_k or len(nums) == 3
        rows.append((nums[0], nums[1], nums[2] if len(nums) == 3 else 0.0))
    if len(rows) < 2:
        raise DispersionError(f"{source}: needs at least 2 rows of 'wavelength_nm n [k]'")
    wl, n, k = zip(*rows, strict=True)
    return Tabulated(tuple(wl), tuple(n), tuple(k) if has_k else (), source=source)


#: Aluminium (Rakic et al. 1998, Lorentz-Drude fit, rounded): flake metal of silver metallics.
ALUMINIUM = Tabulated(
    wavelengths_nm=(380.0, 400.0, 450.0, 500.0, 550.0, 600.0, 650.0, 700.0, 750.0, 780.0),
    n=(0.41, 0.49, 0.62, 0.77, 0.96, 1.20, 1.47, 1.83, 2.30, 2.62),
    k=(4.61, 4.86, 5.47, 6.08, 6.69, 7.26, 7.79, 8.31, 8.62, 8.60),
    source="aluminium (Rakic 1998)",
)


def dispersion_from_dict(
    spec: Mapping[str, Any] | float | complex, *, where: str = "n", tables: Mapping[str, str] = {}
) -> Dispersion:
    """A dispersion from a config value: a number, or a table with ``kind``.

    ``{kind = "cauchy", A = 1.50, B = 0.0042}``, ``{kind = "sellmeier", B = [...], C = [...]}``,
    ``{kind = "table", file = "coat.csv"}`` (``tables`` maps file names to their text, read
    by the caller: this module does no I/O), ``{kind = "aluminium"}``, or ``1.55``.

    Raises
    ------
    DispersionError
        ``where: reason``.
    """
    if isinstance(spec, int | float | complex) and not isinstance(spec, bool):
        return Constant(complex(spec))
    if not isinstance(spec, Mapping):
        raise DispersionError(
            f"{where}: expected a number or a table with a kind, got {repr(spec)[:60]}"
        )
    kind = str(spec.get("kind", ""))
    try:
        if kind == "constant":
            return Constant(complex(float(spec["n"]), float(spec.get("k", 0.0))))
        if kind == "cauchy":
            return Cauchy(float(spec["A"]), float(spec.get("B", 0.0)), float(spec.get("C", 0.0)))
        if kind == "sellmeier":
            return Sellmeier(tuple(float(b) for b in spec["B"]), tuple(float(c) for c in spec["C"]))
        if kind == "aluminium":
            return ALUMINIUM
        if kind == "table":
            name = str(spec["file"])
            if name not in tables:
                raise DispersionError(f"{where}: table file {name!r} was not read")
            return parse_nk_table(tables[name], source=name)
    except KeyError as exc:
        raise DispersionError(f"{where}: {kind} needs the key {exc.args[0]!r}") from None
    except (TypeError, ValueError) as exc:
        if isinstance(exc, DispersionError):
            raise
        raise DispersionError(f"{where}: {exc}") from None
    raise DispersionError(
        f"{where}: unknown kind {kind!r} (constant, cauchy, sellmeier, table, aluminium)"
    )


def as_dispersion(value: Dispersion | complex | float) -> Dispersion:
    """A :class:`Dispersion`, wrapping a plain number as :class:`Constant`."""
    if isinstance(value, Dispersion):
        return value
    if isinstance(value, int | float | complex) and math.isfinite(abs(complex(value))):
        return Constant(complex(value))
    raise DispersionError(f"not a refractive index: {value!r}")


def sample_index(d: Dispersion, wavelengths_nm: Sequence[float]) -> ComplexArray:
    """``d.index`` on a grid after :meth:`Dispersion.check_covers`."""
    d.check_covers(wavelengths_nm)
    return d.index(wavelengths_nm)

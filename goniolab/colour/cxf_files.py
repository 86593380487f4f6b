"""Measured multi-angle spectra from a CxF3 file (ISO 17972-1, the Color Exchange Format).

CxF3 (X-Rite's Color Exchange Format, standardised as ISO 17972-1:2015, schema
``http://colorexchangeformat.com/CxF3-core``) is what multi-angle instruments' software
(X-Rite MA-series, BYK-mac's smart-chart) exports besides CSV. The XML is parsed by
``colour-cxf`` (Colour Developers, BSD-3-Clause; the optional extra ``goniolab[cxf]``),
whose dataclasses are generated from the CxF3 core schema; this module maps them onto
:class:`goniolab.colour.exchange.MultiAngleSpectra`, the same table the CSV reader gives,
so ``predict colour --compare FILE.cxf`` takes the same path as a CSV file.

What is read, per ``Object`` of the ``ObjectCollection``:

- every ``ReflectanceSpectrum`` (values from ``StartWL`` -- on the spectrum, else the
  specification's ``WavelengthRange`` -- in steps of the ``WavelengthRange``'s
  ``Increment``) and every ``CustomSpectrum`` (``SpectralPoint WL=...`` lists);
- its geometry from the ``ColorSpecification`` it names: ``MeasurementSpec /
  GeometryChoice / MultiAngle / BRDFAngle`` gives ``IlluminationAngle`` (theta_i) and
  ``Aspecular`` ("the in-plane viewing angle" from the specular direction, positive towards
  the lamp, as in ASTM E2194), so ``theta_r = theta_i - aspecular``
  (:func:`goniolab.colour.multiangle.theta_r_for_aspecular`; 45as15 -> theta_r 30). A
  ``MultiAngle`` with several ``BRDFAngle`` elements is resolved by the spectrum's ``Name``
  equal to a ``BRDFAngle``'s ``Notation``.
- values: the schema's ``Spectrum_Reflectance`` is "scaled such that 100% = 1.0"
  (reflectance factors, CxF3 core schema, ``eSpectrumType``; the schema bounds them to
  -0.1 < value < 3.0, so percentages written into a CxF3 file are refused, not rescaled); a
  ``LuminanceUnitsType`` other than ``normalized`` is refused.

Refused, naming the file, the object and the reason: no geometry (``UnknownGeometry`` or
none), a sphere (d/8) geometry, an out-of-plane ``Azimuth``, transmittance or emissive
spectra, a spectrum whose grid is not stated, a specification the file does not define.
Single-angle data (``SingleAngle``, e.g. 45/0) is not multi-angle data: it is read as one
geometry only when its angles are explicit and the detector's side is not in doubt (one of
the two angles is 0), and a note says so.

References
----------
.. [1] ISO 17972-1:2015, Graphic technology -- Colour data exchange format (CxF/X) --
   Part 1: Relationship to CxF3 (CxF/X); X-Rite, CxF3 core schema ``CxF3_Core.xsd``.
.. [2] ASTM E2194-14, multiangle colour of metal flake pigmented materials (aspecular
   angles).
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from goniolab.colour.exchange import FloatArray, MultiAngleSpectra
from goniolab.colour.multiangle import theta_r_for_aspecular
from goniolab.colour.spectra import ColourError, check_spectrum

__all__ = ["CXF3_NAMESPACE", "CXF_INSTALL_HINT", "is_cxf3", "read_spectra_cxf"]

#: The CxF3 core namespace (CxF3_Core.xsd ``targetNamespace``).
CXF3_NAMESPACE = "http://colorexchangeformat.com/CxF3-core"
CXF_INSTALL_HINT = "pip install 'goniolab[cxf]'"
_ROOT = re.compile(rb"<(?:[A-Za-z_][\w.-]*:)?CxF[\s>/]")
#: CxF3_Core.xsd: ReflectanceSpectrum values are restricted to -0.1 < value < 3.0
_SCHEMA_MAX = 3.0
_DTD = re.compile(rb"<!(?:DOCTYPE|ENTITY)", re.IGNORECASE)


def is_cxf3(data: bytes) -> bool:
    """Whether ``data`` is an XML document in the CxF3 namespace (its first 4 kB)."""
    head = data[:4096]
    return CXF3_NAMESPACE.encode() in head and _ROOT.search(head) is not None


def _cxf_module(where: str) -> Any:
    try:
        import colour_cxf
    except ImportError:
        raise ColourError(
            f"{where}: reading CxF3 needs the colour-cxf package: {CXF_INSTALL_HINT}"
        ) from None
    return colour_cxf


def _geometry(spec: Any, name: str | None, w: str) -> tuple[float, float, str]:
    """``(theta_i_deg, theta_r_deg, note)`` of a ColorSpecification's geometry."""
    ms = spec.measurement_spec
    choice: Any = None if ms is None or ms.geometry_choice is None else ms.geometry_choice.choice
    kind = type(choice).__name__
    if kind == "MultiAngleType":
        angles = list(choice.brdfangle)
        if len(angles) > 1:
            angles = [a for a in angles if name is not None and a.notation == name]
            if len(angles) != 1:
                raise ColourError(
                    f"{w}: specification {spec.id!r} lists {len(choice.brdfangle)} BRDFAngle "
                    f"elements and the spectrum's Name {name!r} matches no single Notation"
                )
        if not angles:
            raise ColourError(f"{w}: specification {spec.id!r}: MultiAngle without a BRDFAngle")
        a = angles[0]
        if a.illumination_angle is None or a.aspecular is None:
            raise ColourError(
                f"{w}: specification {spec.id!r}: BRDFAngle {a.notation!r} lacks "
                "IlluminationAngle or Aspecular"
            )
        if a.azimuth is not None and abs(float(a.azimuth)) > 1e-9:
            raise ColourError(
                f"{w}: BRDFAngle {a.notation!r}: Azimuth {a.azimuth:g} deg is out of the "
                "plane of incidence (goniolab predicts in-plane geometries only)"
            )
        ti = float(a.illumination_angle)
        return ti, theta_r_for_aspecular(float(a.aspecular), ti), ""
    if kind == "SingleAngleType":
        ti_s, tr_s = choice.illumination_angle, choice.measurement_angle
        if ti_s is None or tr_s is None:
            raise ColourError(
                f"{w}: specification {spec.id!r}: SingleAngle without both "
                "IlluminationAngle and MeasurementAngle"
            )
        if abs(float(ti_s)) > 1e-9 and abs(float(tr_s)) > 1e-9:
            raise ColourError(
                f"{w}: specification {spec.id!r}: single angle {ti_s:g}/{tr_s:g} does not say "
                "on which side of the normal the detector sits"
            )
        note = (
            f"{w}: single-angle {ti_s:g}/{tr_s:g} data, not multi-angle data: read as one geometry"
        )
        return float(ti_s), float(tr_s), note
    if kind == "EsphereType":
        raise ColourError(
            f"{w}: specification {spec.id!r}: sphere geometry ({choice.value}), not a "
            "directional (multi-angle) geometry"
        )
    raise ColourError(
        f"{w}: specification {spec.id!r} states no measurement geometry "
        "(needs MeasurementSpec/GeometryChoice/MultiAngle)"
    )


def _wavelengths(spectrum: Any, spec: Any, w: str) -> FloatArray:
    kind = type(spectrum).__name__
    if kind == "CustomSpectrum":
        return np.array([float(p.wl) for p in spectrum.spectral_point])
    wr = getattr(spec.measurement_spec, "wavelength_range", None)
    start = spectrum.start_wl if spectrum.start_wl is not None else getattr(wr, "start_wl", None)
    step = getattr(wr, "increment", None)
    if start is None or step is None:
        raise ColourError(
            f"{w}: the grid is not stated (StartWL and the specification's "
            "WavelengthRange Increment)"
        )
    wl: FloatArray = float(start) + float(step) * np.arange(len(spectrum.value), dtype=np.float64)
    return wl


def read_spectra_cxf(data: bytes, *, where: str = "cxf") -> MultiAngleSpectra:
    """Reflectance-factor spectra per object and geometry from a CxF3 document.

    Parameters
    ----------
    data
        The file's bytes.
    where
        The file's name, which every message starts with.

    Returns
    -------
    MultiAngleSpectra
        One row per spectrum; ``source`` is the object's ``Name``, ``repeat`` numbers the
        spectra of one object at one geometry; ``notes`` says what was read as what
        (single-angle data).

    Raises
    ------
    ColourError
        ``where: object NAME: reason`` for what cannot be mapped (module docstring); also
        when colour-cxf is not installed (naming ``pip install 'goniolab[cxf]'``).
    """
    if not is_cxf3(data):
        raise ColourError(f"{where}: not a CxF3 document (no <CxF> in {CXF3_NAMESPACE})")
    if _DTD.search(data):  # no DTD in CxF3; refused so no entity is ever expanded
        raise ColourError(
            f"{where}: has a <!DOCTYPE>/<!ENTITY> declaration, which a CxF3 document does not "
            "have: refused"
        )
    cxf = _cxf_module(where)
    try:
        doc = cxf.read_cxf(data)
    except ValueError as exc:  # xsdata's ParserError: malformed XML or a schema mismatch
        raise ColourError(f"{where}: not readable as CxF3: {exc}") from None
    res = doc.resources
    specs = {} if res is None or res.color_specification_collection is None else {
        s.id: s for s in res.color_specification_collection.color_specification}  # fmt: skip
    objects = [] if res is None or res.object_collection is None else list(
        res.object_collection.object_value)  # fmt: skip
    wl_ref: FloatArray | None = None
    ti_l: list[float] = []
    tr_l: list[float] = []
    fac: list[FloatArray] = []
    src: list[str] = []
    rep: list[int] = []
    notes: list[str] = []
    count: dict[tuple[str, float, float], int] = {}
    for obj in objects:
        oname = obj.name if obj.name else f"Id {obj.id}"
        values = [] if obj.color_values is None else obj.color_values.choice
        for sp in values:
            kind = type(sp).__name__
            if kind not in ("ReflectanceSpectrum", "CustomSpectrum",
                            "TransmittanceSpectrum", "EmissiveSpectrum"):  # fmt: skip
                continue  # L*a*b*, sRGB, ...: not spectra
            w = f"{where}: object {oname!r}, {kind}" + (f" {sp.name!r}" if sp.name else "")
            if kind in ("TransmittanceSpectrum", "EmissiveSpectrum"):
                raise ColourError(f"{w}: not reflectance data")
            spec = specs.get(sp.color_specification)
            if spec is None:
                raise ColourError(
                    f"{w}: ColorSpecification {sp.color_specification!r} is not defined in the file"
                )
            ms = spec.measurement_spec
            mtype = getattr(getattr(ms, "measurement_type", None), "value", None)
            mname = getattr(mtype, "value", mtype)
            if kind == "ReflectanceSpectrum" and mname not in (None, "Spectrum_Reflectance"):
                raise ColourError(
                    f"{w}: MeasurementType {mname} is not reflectance (Spectrum_Reflectance)"
                )
            units = getattr(getattr(ms, "luminance_units_type", None), "value", None)
            if units is not None and getattr(units, "value", units) != "normalized":
                raise ColourError(
                    f"{w}: LuminanceUnitsType {getattr(units, 'value', units)} is not "
                    "normalized reflectance (100% = 1.0)"
                )
            ti, tr, note = _geometry(spec, sp.name, w)
            if note and note not in notes:
                notes.append(note)
            wl = _wavelengths(sp, spec, w)
            vals = np.array(
                [float(p.value) for p in sp.spectral_point] if kind == "CustomSpectrum"
                else [float(v) for v in sp.value]
            )  # fmt: skip
            check_spectrum(wl, vals, what=w)
            if vals.size and float(vals.max()) >= _SCHEMA_MAX:
                raise ColourError(
                    f"{w}: a value of {float(vals.max()):g} is outside the schema's range for "
                    f"reflectance factors (below {_SCHEMA_MAX:g}; 100% = 1.0): percent?"
                )
            if wl_ref is None:
                wl_ref = wl
            elif wl.shape != wl_ref.shape or not np.allclose(wl, wl_ref, rtol=0, atol=1e-9):
                raise ColourError(
                    f"{w}: grid {wl[0]:g}-{wl[-1]:g} nm ({wl.size} values) differs from the "
                    f"file's first spectrum ({wl_ref[0]:g}-{wl_ref[-1]:g} nm, {wl_ref.size})"
                )
            key = (oname, round(ti, 6), round(tr, 6))
            rep.append(count.get(key, 0))
            count[key] = rep[-1] + 1
            ti_l.append(ti)
            tr_l.append(tr)
            fac.append(vals)
            src.append(oname)
    if wl_ref is None:
        raise ColourError(f"{where}: no reflectance spectra in the file's objects")
    return MultiAngleSpectra(
        wl_ref, np.array(ti_l), np.array(tr_l), np.array(fac), tuple(src), tuple(rep),
        notes=tuple(notes),
    )  # fmt: skip

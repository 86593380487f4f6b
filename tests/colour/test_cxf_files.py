"""Measured multi-angle spectra from CxF3 files (issue 25, spectral exchange).

The truth: CxF3 documents written by colour-cxf's own serializer (``colour_cxf.write_cxf``,
from the dataclasses generated from the CxF3 core schema) with known spectra and geometries;
reading them must give those numbers back exactly, and ``predict colour --compare`` of the
CxF3 file must give what ``--compare`` of the same table as CSV gives.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest

from goniolab.cli import main
from goniolab.colour.cxf_files import is_cxf3, read_spectra_cxf
from goniolab.colour.spectra import ColourError

cxf3 = pytest.importorskip("colour_cxf.cxf3")
colour_cxf = pytest.importorskip("colour_cxf")

WL = list(range(400, 701, 20))
ROWS = [  # aspecular (E2194), a spectrum (reflectance factors): the repeat at 45 is a 2nd one
    (15.0, [0.5 + 0.01 * k for k in range(len(WL))]),
    (45.0, [0.125 + 0.002 * k for k in range(len(WL))]),
    (45.0, [0.1275 + 0.002 * k for k in range(len(WL))]),
    (110.0, [0.0625 + 0.001 * k for k in range(len(WL))]),
]


def _spec(sid: str, geometry: Any, start: int = 400, step: int = 20) -> Any:
    return cxf3.ColorSpecification(
        id=sid,
        measurement_spec=cxf3.MeasurementSpec(
            measurement_type=cxf3.MeasurementType(cxf3.EspectrumType.SPECTRUM_REFLECTANCE),
            geometry_choice=cxf3.GeometryChoice(choice=geometry),
            wavelength_range=cxf3.WavelengthRange(start_wl=start, increment=step),
        ),
    )


def _angle(asp: float, ti: float = 45.0, azimuth: float | None = None) -> Any:
    return cxf3.Brdfangle(illumination_angle=ti, aspecular=asp, azimuth=azimuth,
                          notation=f"{ti:g}as{asp:g}")  # fmt: skip


def _doc(specs: list[Any], spectra: list[Any], names: tuple[str, ...] = ("panel 1",)) -> bytes:
    """One object per name, each with all ``spectra``."""
    objs = [
        cxf3.Object(
            object_type="Standard", name=name, id=str(k),
            creation_date=cxf3.CreationDate("2026-11-26T00:00:00Z"),
            color_values=cxf3.ColorValues(choice=spectra),
        )
        for k, name in enumerate(names, start=1)
    ]  # fmt: skip
    doc = cxf3.CxF(
        resources=cxf3.Resources(
            object_collection=cxf3.ObjectCollection(object_value=objs),
            color_specification_collection=cxf3.ColorSpecificationCollection(
                color_specification=specs
            ),
        )
    )
    data: bytes = colour_cxf.write_cxf(doc)
    return data


def _multi_angle(one_spec_per_angle: bool = True) -> bytes:
    """ROWS as an MA-series file: one ColorSpecification per angle, or one MultiAngle
    specification whose BRDFAngle is picked by the spectrum's Name (= its Notation)."""
    angles = sorted({a for a, _ in ROWS})
    if one_spec_per_angle:
        specs = [_spec(f"CS{a:g}", cxf3.MultiAngleType([_angle(a)])) for a in angles]
        ref = [(f"CS{a:g}", None) for a, _ in ROWS]
    else:
        specs = [_spec("MA", cxf3.MultiAngleType([_angle(a) for a in angles]))]
        ref = [("MA", f"45as{a:g}") for a, _ in ROWS]
    spectra = [cxf3.ReflectanceSpectrum(value=v, color_specification=cs, name=nm)
               for (_, v), (cs, nm) in zip(ROWS, ref, strict=True)]  # fmt: skip
    return _doc(specs, spectra)


@pytest.mark.parametrize("one_spec_per_angle", [True, False])
def test_a_written_multi_angle_file_reads_back_exactly(one_spec_per_angle: bool) -> None:
    data = _multi_angle(one_spec_per_angle)
    assert is_cxf3(data) and b"BRDFAngle" in data
    table = read_spectra_cxf(data, where="ma.cxf")
    assert table.wavelengths_nm.tolist() == [float(w) for w in WL]
    assert table.factors.tolist() == [v for _, v in ROWS]
    assert table.theta_i_deg.tolist() == [45.0] * 4
    # E2194: aspecular 15 -> theta_r 30, 45 -> the normal, 110 -> -65 (lamp side)
    assert table.theta_r_deg.tolist() == [30.0, 0.0, 0.0, -65.0]
    assert table.aspecular_deg.tolist() == [a for a, _ in ROWS]
    assert table.source == ("panel 1",) * 4 and table.repeat == (0, 0, 1, 0)
    assert table.notes == ()


def _csv() -> str:
    head = ",".join(["aspecular_deg"] + [f"R_{w}" for w in WL])
    body = [",".join([f"{a:g}"] + [repr(v) for v in vals]) for a, vals in ROWS]
    return "\n".join([head, *body]) + "\n"


def test_compare_of_the_cxf_file_equals_compare_of_the_same_csv(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "lab.csv").write_text(_csv(), encoding="utf-8")
    (tmp_path / "lab.cxf").write_bytes(_multi_angle())
    (tmp_path / "export.xml").write_bytes(_multi_angle(False))  # found by its namespace
    args = ["predict", "colour", "sample:solid-red", "--step-nm", "20", "--json", "--compare"]
    docs = []
    for name in ("lab.csv", "lab.cxf", "export.xml"):
        assert main([*args, str(tmp_path / name)]) == 0
        docs.append(json.loads(capsys.readouterr().out)["compare"])
    for doc in docs:
        doc.pop("file"), doc["pair"].pop("reference")
    assert docs[0]["rows_read"] == 4 and len(docs[0]["measured_lab"]) == 3
    assert docs[1] == docs[0] and docs[2] == docs[0]


def _refused(data: bytes, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> str:
    f = tmp_path / "bad.cxf"
    f.write_bytes(data)
    args = ["predict", "colour", "sample:solid-red", "--step-nm", "20", "--compare", str(f)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err  # one line, no traceback
    return err


def test_a_file_without_geometry_is_refused_naming_file_object_and_reason(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = _doc([_spec("CS1", "not stated")],
                [cxf3.ReflectanceSpectrum(value=ROWS[0][1], color_specification="CS1")])  # fmt: skip
    assert b"UnknownGeometry" in data
    err = _refused(data, tmp_path, capsys)
    assert f"{tmp_path / 'bad.cxf'}: object 'panel 1', ReflectanceSpectrum" in err
    assert "specification 'CS1' states no measurement geometry" in err


def test_corrupt_xml_is_refused_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = _multi_angle()
    err = _refused(data[: len(data) // 2], tmp_path, capsys)
    assert f"{tmp_path / 'bad.cxf'}: not readable as CxF3: " in err
    err = _refused(b"R_400,R_500\n", tmp_path, capsys)  # a CSV renamed .cxf
    assert "not a CxF3 document" in err
    entity = b'<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaa">]>' + data.split(b"?>", 1)[1]
    err = _refused(entity, tmp_path, capsys)  # no entity expansion ("billion laughs")
    assert "has a <!DOCTYPE>/<!ENTITY> declaration" in err


def test_a_missing_library_names_the_extra(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "colour_cxf", None)  # `import colour_cxf` -> ImportError
    err = _refused(_multi_angle(), tmp_path, capsys)
    assert "reading CxF3 needs the colour-cxf package: pip install 'goniolab[cxf]'" in err


@pytest.mark.parametrize(
    ("geometry", "needle"),
    [
        (cxf3.SingleAngleType(illumination_angle=45.0, measurement_angle=8.0),
         "single angle 45/8 does not say on which side"),
        (cxf3.MultiAngleType([_angle(15.0, azimuth=90.0)]), "Azimuth 90 deg is out of the plane"),
        (cxf3.MultiAngleType([_angle(15.0), _angle(45.0)]), "matches no single Notation"),
    ],
)  # fmt: skip
def test_geometries_that_cannot_be_mapped_are_refused(geometry: Any, needle: str) -> None:
    data = _doc([_spec("CS1", geometry)],
                [cxf3.ReflectanceSpectrum(value=ROWS[0][1], color_specification="CS1")])  # fmt: skip
    with pytest.raises(ColourError, match=needle):
        read_spectra_cxf(data, where="x.cxf")


def test_single_angle_45_0_is_one_geometry_and_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    geometry = cxf3.SingleAngleType(
        single_angle_configuration=cxf3.SingleAngleConfiguration(
            cxf3.EsingleAngleConfigurationType.ANNULAR
        ),
        illumination_angle=45.0,
        measurement_angle=0.0,
    )
    data = _doc([_spec("CS1", geometry)],
                [cxf3.ReflectanceSpectrum(value=ROWS[1][1], color_specification="CS1")])  # fmt: skip
    table = read_spectra_cxf(data, where="x.cxf")
    assert (table.theta_i_deg.tolist(), table.theta_r_deg.tolist()) == ([45.0], [0.0])
    assert table.notes == ("x.cxf: object 'panel 1', ReflectanceSpectrum: single-angle 45/0 "
                           "data, not multi-angle data: read as one geometry",)  # fmt: skip
    f = tmp_path / "d45.cxf"
    f.write_bytes(data)
    args = ["predict", "colour", "sample:solid-red", "--step-nm", "20", "--json", "--compare"]
    assert main([*args, str(f)]) == 0
    notes = json.loads(capsys.readouterr().out)["compare"]["spectra_notes"]
    assert (
        f"{f}: object 'panel 1', ReflectanceSpectrum: single-angle 45/0 data, not multi-angle "
        "data: read as one geometry"
    ) in notes


def test_custom_spectrum_points_and_percent_units_refused() -> None:
    pts = [cxf3.SpectralPoint(value=v, wl=w) for w, v in zip(WL, ROWS[0][1], strict=True)]
    data = _doc([_spec("CS1", cxf3.MultiAngleType([_angle(15.0)]))],
                [cxf3.CustomSpectrum(spectral_point=pts, color_specification="CS1")])  # fmt: skip
    table = read_spectra_cxf(data, where="x.cxf")
    assert table.factors.tolist() == [ROWS[0][1]] and table.theta_r_deg.tolist() == [30.0]
    spec = _spec("CS1", cxf3.MultiAngleType([_angle(15.0)]))
    spec.measurement_spec.luminance_units_type = cxf3.LuminanceUnitsType(cxf3.EluminanceUnits.CD_M2)
    data = _doc([spec], [cxf3.ReflectanceSpectrum(value=ROWS[0][1], color_specification="CS1")])
    with pytest.raises(ColourError, match="LuminanceUnitsType cd/m2 is not normalized"):
        read_spectra_cxf(data, where="x.cxf")
    pct = [100 * v for v in ROWS[0][1]]  # percent written where the schema wants factors
    data = _doc([_spec("CS1", cxf3.MultiAngleType([_angle(15.0)]))],
                [cxf3.ReflectanceSpectrum(value=pct, color_specification="CS1")])  # fmt: skip
    with pytest.raises(ColourError, match=r"a value of 65 is outside the schema's range"):
        read_spectra_cxf(data, where="x.cxf")


def test_percent_units_and_several_objects_are_refused_for_compare(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    f = tmp_path / "lab.cxf"
    f.write_bytes(_multi_angle())
    args = ["predict", "colour", "sample:solid-red", "--step-nm", "20", "--compare", str(f)]
    assert main([*args, "--compare-unit", "percent"]) == 2
    assert "CxF3 spectra are reflectance factors (100% = 1.0)" in capsys.readouterr().err
    spectra = [cxf3.ReflectanceSpectrum(value=ROWS[0][1], color_specification="CS1")]
    data = _doc([_spec("CS1", cxf3.MultiAngleType([_angle(15.0)]))], spectra, ("std", "trial"))
    assert read_spectra_cxf(data).source == ("std", "trial")
    err = _refused(data, tmp_path, capsys)
    assert f"--compare {tmp_path / 'bad.cxf'}: one object per file, found std, trial" in err


def test_the_sample_shipped_with_colour_cxf_is_refused_for_its_range() -> None:
    """colour-cxf's own test file (an X-Rite ColorPort target, 45/0 annular, StartWL 380,
    Increment 10, 31 values: 380-680 nm) is read down to its grid, which misses 700 nm."""
    sample = Path(colour_cxf.__file__).parent / "tests" / "resources" / "sample.cxf"
    if not sample.is_file():
        pytest.skip("this colour-cxf build ships no sample.cxf")
    with pytest.raises(ColourError) as err:
        read_spectra_cxf(sample.read_bytes(), where="sample.cxf")
    assert str(err.value) == (
        "sample.cxf: object '1', ReflectanceSpectrum: wavelengths 380-680 nm do not cover "
        "400-700 nm"
    )

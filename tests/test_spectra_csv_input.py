"""A lab's measured multi-angle spectra as its spreadsheet writes them (issue 25).

``predict colour --compare FILE.csv`` reads an instrument's spectra. A file saved by Excel
as "CSV UTF-8" starts with a byte-order mark; a German or French Excel writes semicolons
between cells and decimal commas inside them, or tabs. Each such file must read as the
plain comma file it is the same table as (the truth), and a bad cell must be named by file,
line and column, also in an angle column.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.colour.exchange import read_spectra_csv
from goniolab.colour.spectra import ColourError

WL = list(range(400, 701, 20))
ROWS = [  # aspecular, repeat, a spectrum (reflectance factors)
    (15.0, 0, [0.5 + 0.01 * k for k in range(len(WL))]),
    (45.0, 0, [0.125 + 0.002 * k for k in range(len(WL))]),
    (45.0, 1, [0.1275 + 0.002 * k for k in range(len(WL))]),
]


def _plain() -> str:
    head = ",".join(["aspecular_deg", "repeat"] + [f"R_{w}" for w in WL])
    body = [",".join([f"{a:g}", str(r)] + [f"{v:g}" for v in vals]) for a, r, vals in ROWS]
    return "\n".join([head, *body]) + "\n"


def _spreadsheet(sep: str, bom: bool = False) -> str:
    """The same table as a spreadsheet in a comma-decimal locale writes it."""
    text = _plain().replace(",", sep)
    if sep != ",":
        text = text.replace(".", ",")
    return ("\ufeff" if bom else "") + text


@pytest.mark.parametrize(("sep", "bom"), [(",", True), (";", False), (";", True), ("\t", False)])
def test_a_spreadsheets_csv_reads_as_the_plain_file(sep: str, bom: bool) -> None:
    want = read_spectra_csv(_plain(), where="lab.csv")
    got = read_spectra_csv(_spreadsheet(sep, bom), where="lab.csv")
    np.testing.assert_array_equal(got.factors, want.factors)
    np.testing.assert_array_equal(got.wavelengths_nm, np.array(WL, dtype=float))
    np.testing.assert_array_equal(got.aspecular_deg, [15.0, 45.0, 45.0])
    assert got.repeat == (0, 0, 1)
    np.testing.assert_array_equal(got.factors[2], [float(f"{v:g}") for v in ROWS[2][2]])


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        (
            "aspecular_deg,R_400,R_500,R_600,R_700\nx,1,1,1,1\n",
            "lab.csv: line 2, aspecular_deg: 'x'",
        ),
        ("theta_r_deg;R_400;R_500;R_600;R_700\n30;1;1;1,5.;1\n", "lab.csv: line 2, R_600: '1,5.'"),
        ("aspecular_deg,repeat,R_400,R_500,R_600,R_700\n15,one,1,1,1,1\n", "line 2, repeat: 'one'"),
        (
            "\ufeffaspecular_deg,R_400,R_500,R_600,R_700\n15,1,1,1\n",
            "line 2: 4 cells for 5 columns",
        ),
    ],
)
def test_bad_cells_are_named_by_file_line_and_column(text: str, needle: str) -> None:
    with pytest.raises(ColourError, match=needle):
        read_spectra_csv(text, where="lab.csv")


def test_compare_reads_a_semicolon_file_like_the_comma_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["predict", "colour", "sample:solid-red", "--step-nm", "20", "--json", "--compare"]
    docs = []
    for name, text in (("plain.csv", _plain()), ("excel.csv", _spreadsheet(";", bom=True))):
        (tmp_path / name).write_text(text, encoding="utf-8")
        assert main([*args, str(tmp_path / name)]) == 0
        docs.append(json.loads(capsys.readouterr().out)["compare"])
    for doc in docs:
        doc.pop("file"), doc["pair"].pop("reference")
    assert docs[0] == docs[1] and docs[0]["rows_read"] == 3


def test_a_file_in_a_windows_code_page_is_refused_naming_the_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Excel's plain "CSV" on Windows writes cp1252 (a degree sign is byte 0xb0): refused in
    one line naming the file and line, not read in a guessed encoding (nor a traceback)."""
    f = tmp_path / "cp1252.csv"
    f.write_bytes(_plain().encode() + "# theta_i 45\u00b0\n".encode("cp1252"))
    args = ["predict", "colour", "sample:solid-red", "--step-nm", "20", "--compare", str(f)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert f"--compare {f}: line 5: byte 0xb0 is not UTF-8 text" in err
    assert err.count("\n") == 1


def test_percentages_read_as_factors_are_pointed_out(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Every value above 1 (here: the table in percent) is said, with the option that reads
    percent; the same file with ``--compare-unit percent``, and the factor file, say nothing."""
    pct = _plain().splitlines()
    pct = [pct[0]] + [
        ",".join(c if k < 2 else f"{100 * float(c):g}" for k, c in enumerate(row.split(",")))
        for row in pct[1:]
    ]
    f = tmp_path / "pct.csv"
    f.write_text("\n".join(pct) + "\n")
    (tmp_path / "factor.csv").write_text(_plain())
    args = ["predict", "colour", "sample:solid-red", "--step-nm", "20", "--json", "--compare"]
    notes = []
    for extra in ([str(f)], [str(f), "--compare-unit", "percent"], [str(tmp_path / "factor.csv")]):
        assert main([*args, *extra]) == 0
        notes.append(json.loads(capsys.readouterr().out)["compare"]["spectra_notes"])
    # the lowest: 45 deg's two repeats averaged as spectra, (12.5 + 12.75) / 2 at 400 nm
    said = (
        f"every value of {f} is above 1 (the lowest 12.6): read as reflectance factors; "
        "if they are percentages, pass --compare-unit percent"
    )
    assert said in notes[0]
    assert notes[1] == notes[2] == [n for n in notes[0] if n != said]

"""``goniolab samples save NAME FILE`` (issue 27, item 3): every file-based example of the
README can start from a file goniolab wrote. Each format is read back and compared with
the sample itself (the generator's map), within what the format stores."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from goniolab.cli import main
from goniolab.surfaces.registry import load_heightmap
from goniolab.surfaces.synthetic import make_sample


@pytest.mark.parametrize(
    ("suffix", "exact"),
    [(".npy", True), (".csv", True), (".sdf", True), (".gwy", True), (".sur", False)],
)
def test_save_writes_the_sample_in_the_format_of_the_extension(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], suffix: str, exact: bool
) -> None:
    path = tmp_path / f"scan{suffix}"
    code = main(["samples", "save", "wittmann-3", str(path), "--size", "48", "--step-um", "0.5",
                 "--json"])  # fmt: skip
    assert code == 0
    info = json.loads(capsys.readouterr().out)
    assert info == {
        "sample": "sample:wittmann-3",
        "file": str(path),
        "shape": [48, 48],
        "step_um": [0.5, 0.5],
        "field_um": [24.0, 24.0],
    }
    truth = make_sample("wittmann-3", size=48, step_um=0.5)
    read = load_heightmap(path)
    assert (read.dx_um, read.dy_um) == (0.5, 0.5)
    if exact:  # float formats: to the last bit (gwy stores metres: 1 ulp)
        np.testing.assert_allclose(read.z_um, truth.z_um, rtol=1e-15, atol=1e-15)
    else:  # .sur stores int32 with a z step: within half of it
        step = float(read.meta["z_step_um"])
        assert np.max(np.abs(read.z_um - truth.z_um)) <= 0.5 * step + 1e-12


def test_save_refuses_to_overwrite_and_suggests_names(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "scan.sur"
    path.write_bytes(b"keep me")
    assert main(["samples", "save", "flat", str(path)]) == 2
    assert "exists; pass --force" in capsys.readouterr().err
    assert path.read_bytes() == b"keep me"
    assert main(["samples", "save", "wittman-3", str(tmp_path / "x.sur")]) == 2
    assert "did you mean 'wittmann-3'?" in capsys.readouterr().err
    assert main(["samples", "save", "flat", str(tmp_path / "x.xyz")]) == 2
    assert "unknown height-map extension '.xyz'" in capsys.readouterr().err


def test_a_saved_file_predicts_as_the_sample_does(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # the README's first file example: the gloss of the saved file is the sample's
    path = tmp_path / "scan.npy"
    assert main(["samples", "save", "wittmann-3", str(path)]) == 0  # the library's 512^2
    capsys.readouterr()
    assert main(["predict", "gloss", str(path), "--n", "1.55", "--json"]) == 0
    from_file = json.loads(capsys.readouterr().out)
    assert main(["predict", "gloss", "sample:wittmann-3", "--n", "1.55", "--json"]) == 0
    from_sample = json.loads(capsys.readouterr().out)
    for key in ("G20", "G60", "G85"):
        assert from_file[key] == pytest.approx(from_sample[key], rel=1e-12)
    assert from_file["model"] == from_sample["model"]

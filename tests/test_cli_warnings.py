"""goniolab's own warnings are one line on stderr; a library's go to the log file (and to
stderr only under --debug), never dressed as ``goniolab: warning:`` (issue 23, Low)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from goniolab import cli
from goniolab.surfaces.npy import HeightUnitsWarning


@pytest.fixture
def show(monkeypatch: pytest.MonkeyPatch) -> object:
    monkeypatch.setattr(warnings, "showwarning", warnings.showwarning)  # restored after
    return warnings


def test_a_library_warning_goes_to_the_log_only(
    show: object, capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    cli._one_line_warnings(debug=False)
    numpy_file = str(Path(np.__file__).with_name("_methods.py"))
    warnings.showwarning(RuntimeWarning("Mean of empty slice"), RuntimeWarning, numpy_file, 7)
    assert capsys.readouterr().err == ""
    assert "library warning (RuntimeWarning from" in caplog.text
    assert "Mean of empty slice" in caplog.text


def test_a_library_warning_shows_under_debug_with_its_origin(
    show: object, capsys: pytest.CaptureFixture[str]
) -> None:
    cli._one_line_warnings(debug=True)
    warnings.showwarning(FutureWarning("old API"), FutureWarning, "/x/pandas/core/frame.py", 3)
    err = capsys.readouterr().err
    assert err.startswith("goniolab: library warning (FutureWarning from /x/pandas/core")
    assert "goniolab: warning:" not in err


def test_goniolab_warnings_stay_one_line(show: object, capsys: pytest.CaptureFixture[str]) -> None:
    cli._one_line_warnings(debug=False)
    # its own class, raised on behalf of a caller anywhere (stacklevel=2)
    warnings.showwarning(HeightUnitsWarning("m.npy: nm?"), HeightUnitsWarning, "/home/u/x.py", 1)
    # a plain UserWarning from goniolab's own code
    own = str(Path(cli.__file__).with_name("datasets.py"))
    warnings.showwarning(UserWarning("ours"), UserWarning, own, 1)
    assert capsys.readouterr().err == "goniolab: warning: m.npy: nm?\ngoniolab: warning: ours\n"

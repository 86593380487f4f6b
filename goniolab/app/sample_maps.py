"""The built-in synthetic samples: list them (``goniolab samples``) and write one as a
height-map file (``goniolab samples save``), so that every file-based example has a file to
start from (:mod:`goniolab.surfaces.synthetic`, :mod:`goniolab.surfaces.registry`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from goniolab.errors import UserError

__all__ = ["SavedSample", "list_samples", "save_sample"]


def list_samples() -> list[Any]:
    """Every built-in sample's :class:`goniolab.surfaces.synthetic.SampleInfo` (name,
    description, index, the seed paper's Ra and G60: Wittmann et al. 2021, table 1)."""
    from goniolab.surfaces.synthetic import SampleError, sample_info, sample_names

    try:
        return [sample_info(name) for name in sample_names()]
    except SampleError as exc:
        raise UserError(str(exc)) from None


@dataclass(frozen=True)
class SavedSample:
    """A sample written to ``file``: its shape ``(ny, nx)`` and steps, um."""

    sample: str
    file: Path
    shape: tuple[int, int]
    dx_um: float
    dy_um: float

    def as_dict(self) -> dict[str, Any]:
        """``samples save --json``."""
        ny, nx = self.shape
        return {
            "sample": self.sample,
            "file": str(self.file),
            "shape": [ny, nx],
            "step_um": [self.dx_um, self.dy_um],
            "field_um": [nx * self.dx_um, ny * self.dy_um],
        }


def save_sample(
    name: str,
    file: str | Path,
    *,
    size: int | None = None,
    seed: int | None = None,
    step_um: float | None = None,
    fmt: str | None = None,
    force: bool = False,
) -> SavedSample:
    """Write sample ``name`` (``sample:`` optional) to ``file`` in the format of its
    extension or ``fmt``; an existing file only with ``force``."""
    from goniolab.optics.heightmap import HeightMapError
    from goniolab.surfaces.registry import save_heightmap
    from goniolab.surfaces.synthetic import SampleError, make_sample

    name = name.removeprefix("sample:")
    try:
        hm = make_sample(name, size=size, seed=seed, step_um=step_um)
    except SampleError as exc:
        raise UserError(str(exc)) from None
    path = Path(file)
    if path.exists() and not force:
        raise UserError(f"{path}: exists; pass --force to overwrite it")
    if not path.parent.is_dir():
        raise UserError(f"{path}: no such directory {path.parent}")
    try:
        save_heightmap(hm, path, fmt=fmt)
    except HeightMapError as exc:
        raise UserError(str(exc)) from None
    ny, nx = hm.z_um.shape
    return SavedSample(f"sample:{name}", path, (ny, nx), hm.dx_um, hm.dy_um)

"""The alignment a scan found: written to a per-lab state file (or a config's
``[alignment]`` table) and read back over the config's own values."""

from __future__ import annotations

from pathlib import Path

from pydantic import ValidationError

from drivers.toml_schema import first_issue
from goniolab.config.sections import AlignmentConfig, LabConfig
from goniolab.errors import ConfigError
from labtoml import TomlFileError, read_toml


def write_alignment(path: str | Path, values: dict[str, float | int], *, note: str = "") -> None:
    """Write (or replace) the ``[alignment]`` table of a lab config file.

    The rest of the file, comments included, is kept byte for byte; the table goes at the
    end (an existing ``[alignment]`` table, up to the next table header, is removed
    first). The result is validated before the file is replaced (atomically).

    Raises
    ------
    ConfigError
        The file cannot be read or written, or the values are out of range.
    """
    import re

    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(p, "alignment", f"cannot read the config to write it: {exc}") from None
    text = re.sub(r"(?ms)^\[alignment\][^\n]*\n(?:(?!^\[).*?\n)*", "", text)
    if not text.endswith("\n"):
        text += "\n"
    lines = [f"[alignment]{'  # ' + note if note else ''}"]
    for key, value in values.items():
        lines.append(f"{key} = {value:.4f}" if isinstance(value, float) else f"{key} = {value}")
    new = text.rstrip("\n") + "\n\n" + "\n".join(lines) + "\n"
    try:
        AlignmentConfig.model_validate(values)
    except ValidationError as exc:
        key, reason = first_issue(exc)
        raise ConfigError(p, f"alignment.{key}", reason) from None
    _replace_text(p, new, key="alignment")


# --------------------------------------------------------------------------- alignment state
#: The keys an alignment state file carries in its ``[alignment]`` table.
_STATE_KEYS = ("lamp_zero_deg", "detector_zero_deg", "sample_tilt_deg", "run")


def alignment_state_path(cfg: LabConfig) -> Path:
    """The per-lab alignment state file of a config (issue 22: never the tracked config).

    ``[alignment] state_file`` relative to the config's directory when set; otherwise
    ``<config stem>.alignment.toml`` beside the store (``[lab] store``: its directory for an
    SQLite file, resolved against the config's directory; the user data directory for the
    default store or a PostgreSQL one).
    """
    import platformdirs

    from goniolab.store import is_store_url

    base = Path(cfg.source).resolve().parent if cfg.source else Path.cwd()
    if cfg.alignment.state_file:
        p = Path(cfg.alignment.state_file).expanduser()
        return p if p.is_absolute() else base / p
    stem = Path(cfg.source).stem if cfg.source else "lab"
    store = cfg.lab.store
    if store and not is_store_url(store):
        sp = Path(store).expanduser()
        return (sp if sp.is_absolute() else base / sp).parent / f"{stem}.alignment.toml"
    return Path(platformdirs.user_data_dir("goniolab", appauthor=False)) / f"{stem}.alignment.toml"


def with_alignment_state(cfg: LabConfig) -> LabConfig:
    """``cfg`` with the values of its alignment state file (if there is one), which cites it.

    Raises
    ------
    ConfigError
        The state file exists but is unreadable or holds out-of-range values (naming it).
    """
    path = alignment_state_path(cfg)
    if not path.is_file():
        return cfg
    try:
        data = read_toml(path, what="alignment state file")
    except TomlFileError as exc:
        raise ConfigError(path, "", exc.reason) from None
    table = data.get("alignment")
    if not isinstance(table, dict):
        raise ConfigError(path, "alignment", "the state file has no [alignment] table")
    values = {k: table[k] for k in _STATE_KEYS if k in table}
    try:
        AlignmentConfig.model_validate(values)
    except ValidationError as exc:
        key, reason = first_issue(exc)
        raise ConfigError(path, f"alignment.{key}", reason) from None
    update = {**values, "loaded_from": str(path)}
    return cfg.model_copy(update={"alignment": cfg.alignment.model_copy(update=update)})


def write_alignment_state(
    cfg: LabConfig, values: dict[str, float | int], *, note: str = ""
) -> Path:
    """Write the alignment result to the config's state file (:func:`alignment_state_path`);
    the config file itself is not touched. Validated first; written atomically (a temp file
    beside it, then ``os.replace``), an existing file's mode kept. Returns the path.

    Raises
    ------
    ConfigError
        Out-of-range values (nothing written) or the file cannot be written.
    """

    path = alignment_state_path(cfg)
    try:
        AlignmentConfig.model_validate(values)
    except ValidationError as exc:
        key, reason = first_issue(exc)
        raise ConfigError(path, f"alignment.{key}", reason) from None
    lines = [
        "# goniolab alignment state: written by `goniolab scan --plan align`, read with the",
        f"# lab config {Path(cfg.source).resolve() if cfg.source else '(none)'}. Not a config.",
    ]
    if note:
        lines.append(f"# {note}")
    lines.append("[alignment]")
    for key, value in values.items():
        lines.append(f"{key} = {value:.4f}" if isinstance(value, float) else f"{key} = {value}")
    _replace_text(path, "\n".join(lines) + "\n", key="alignment")
    return path


def _replace_text(path: Path, text: str, *, key: str) -> None:
    """Replace ``path``'s content atomically, keeping what the file is: a symlink's target is
    replaced (the link stays), and the mode (and owner, where permitted) of an existing file
    are kept (issue 23: a config holding a password must not become world-readable)."""
    import contextlib
    import os

    target = path.resolve() if path.is_symlink() else path
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        st = target.stat() if target.exists() else None
        tmp = target.with_name(target.name + f".{os.getpid()}.tmp")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        if st is not None:
            os.chmod(tmp, st.st_mode & 0o7777)
            with contextlib.suppress(OSError, AttributeError):
                os.chown(tmp, st.st_uid, st.st_gid)
        else:
            os.chmod(tmp, 0o644)
        os.replace(tmp, target)
    except OSError as exc:
        raise ConfigError(path, key, f"cannot write {path}: {exc}") from None

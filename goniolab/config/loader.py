"""Reading a lab config file: :func:`load_lab_config`, and where profiles and the shipped
configs are found (:func:`configs_dir`, :func:`resolve_profile`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError

import goniolab
from drivers.protocols import GLOSSMETERS, SPECTROS, STEPPERS
from drivers.toml_schema import first_issue
from goniolab.config.alignment_state import with_alignment_state
from goniolab.config.checks import cross_checks, exposure_check, register_checks
from goniolab.config.sections import LabConfig
from goniolab.errors import ConfigError
from labtoml import TomlFileError, read_toml


def configs_dir() -> Path:
    """The directory of the shipped configs (source checkout or installed wheel)."""
    here = Path(goniolab.__file__).resolve().parent
    for candidate in (here.parent / "configs", here / "_configs"):
        if candidate.is_dir():
            return candidate
    return here.parent / "configs"


def resolve_profile(name: str, *, relative_to: Path | None = None) -> Path:
    """The file a profile name or path refers to.

    A bare name (``"oriental-az"``) is ``configs/profiles/NAME.toml``; a relative path is
    tried next to the config file (``relative_to``), then under the configs directory.
    """
    if "/" not in name and "\\" not in name and not name.endswith(".toml"):
        return configs_dir() / "profiles" / f"{name}.toml"
    p = Path(name).expanduser()
    if p.is_absolute():
        return p
    if relative_to is not None and (relative_to / p).is_file():
        return relative_to / p
    return configs_dir() / p


def _get(data: dict[str, Any], dotted: str) -> Any:
    node: Any = data
    for part in dotted.split("."):
        node = node.get(part) if isinstance(node, dict) else None
    return node


def load_lab_config(path: str | Path, *, store: str | Path | None = None) -> LabConfig:
    """Read and validate a lab config file.

    Parameters
    ----------
    path
        The TOML file.
    store
        The run store the user chose (``--store``), which replaces ``[lab] store`` before
        the alignment state is looked up: the state lives beside the store a run uses
        (:func:`alignment_state_path`), so two checkouts with their own stores do not
        correct each other's moves. A relative file is relative to the working directory.

    Returns
    -------
    LabConfig
        With profile names replaced by the resolved profile file paths.

    Raises
    ------
    ConfigError
        Missing/unreadable file, TOML syntax error (line and column), unknown key, wrong
        type, out-of-range value or bad device profile; the message names the file, the
        dotted key and the reason.
    """
    p = Path(path)
    try:
        data = read_toml(p, what="config file")
    except TomlFileError as exc:
        raise ConfigError(p, "", exc.reason) from None
    if "source" in data:
        raise ConfigError(p, "source", "unknown key (typo?)")
    try:
        cfg = LabConfig.model_validate({**data, "source": str(p)})
    except ValidationError as exc:
        key, reason = first_issue(exc)
        raise ConfigError(p, key, reason + did_you_mean_key(key, reason)) from None
    except RecursionError:
        raise ConfigError(p, "", TOO_DEEP) from None
    cross_checks(cfg, p)
    cfg, profiles = _resolve_profiles(cfg, p)
    register_checks(cfg, p, profiles)
    exposure_check(cfg, p, profiles["spectro.profile"])
    if store is not None:
        cfg = cfg.model_copy(update={"lab": cfg.lab.model_copy(update={"store": _as_given(store)})})
    return with_alignment_state(cfg)


def _as_given(store: str | Path) -> str:
    """A ``--store`` value as ``[lab] store`` holds it: a URL or conninfo unchanged, a file
    made absolute (the config's relative stores are relative to the config's directory,
    the command line's to the working directory)."""
    from goniolab.store import is_store_url

    text = str(store)
    if is_store_url(text):
        return text
    return str(Path(text).expanduser().resolve())


def did_you_mean_key(key: str, reason: str) -> str:
    """``"; did you mean 'time_scale'?"`` for an unknown ``key`` close to a field of its
    table in :class:`LabConfig` (difflib), else ``""`` (issue 27: config key typos)."""
    import difflib
    import typing

    if not key or "unknown key" not in reason:
        return ""
    *tables, name = key.split(".")
    model: Any = LabConfig
    for part in tables:
        field = model.model_fields.get(part)
        if field is None:
            return ""
        inner = [
            t
            for t in (field.annotation, *typing.get_args(field.annotation))
            if isinstance(t, type) and issubclass(t, BaseModel)
        ]
        if not inner:  # a free-form table (dict): no fixed names to suggest
            return ""
        model = inner[0]
    names = [n for n in model.model_fields if n != "source"]
    close = difflib.get_close_matches(name, names, n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""


#: The reason given for a TOML file nested deeper than the parser's recursion allows.
TOO_DEEP = "arrays or tables nested too deeply to be a lab config"


def _resolve_profiles(cfg: LabConfig, path: Path) -> tuple[LabConfig, dict[str, Any]]:
    """Load every profile the config names; the config with resolved paths, and the
    loaded profiles by config key."""
    from drivers.base import ProfileError  # drivers never import goniolab: this way is allowed

    base = path.resolve().parent
    resolved: dict[str, str] = {}
    loaded: dict[str, Any] = {}
    g = cfg.goniometer
    # each profile is read by the protocol that speaks it (drivers.protocols)
    keys = (
        ("goniometer.lamp.profile", STEPPERS[g.lamp.protocol]),
        ("goniometer.detector.profile", STEPPERS[g.detector.protocol]),
        ("spectro.profile", SPECTROS[cfg.spectro.protocol]),
        ("glossmeter.profile", GLOSSMETERS[cfg.glossmeter.protocol]),
    )
    for key, entry in keys:
        name = _get(cfg.model_dump(), key)
        target = resolve_profile(str(name), relative_to=base)
        try:
            loaded[key] = entry.load_profile(target)
        except ProfileError as exc:
            reason = str(exc)
            if "key 'kind'" in reason:
                reason = f"profile {target} is not a {entry.profile_kind!r} profile ({reason})"
            raise ConfigError(path, key, reason) from None
        resolved[key] = str(target)
    resolved_cfg = cfg.model_copy(
        update={
            "goniometer": g.model_copy(
                update={
                    "lamp": g.lamp.model_copy(
                        update={"profile": resolved["goniometer.lamp.profile"]}
                    ),
                    "detector": g.detector.model_copy(
                        update={"profile": resolved["goniometer.detector.profile"]}
                    ),
                }
            ),
            "spectro": cfg.spectro.model_copy(update={"profile": resolved["spectro.profile"]}),
            "glossmeter": cfg.glossmeter.model_copy(
                update={"profile": resolved["glossmeter.profile"]}
            ),
        }
    )
    return resolved_cfg, loaded

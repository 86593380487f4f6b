"""Lab configuration: the ``configs/lab-*.toml`` files as validated pydantic models.

``load_lab_config(path)`` reads a TOML file into a :class:`LabConfig` (schema in
docs/ARCHITECTURE.md). Unknown keys are errors (``extra="forbid"``): a typo must not fall
back to a default silently. Every problem raises :class:`ConfigError`, a
:class:`goniolab.errors.UserError` whose one-line message names the FILE, the dotted KEY
and the REASON, for example::

    configs/x.toml: goniometer.lamp.limits_deg: lower limit 10 must be below upper limit 5

TOML syntax errors carry the line and column. Reading the file and naming the key of a
pydantic error are shared with the device profiles (:mod:`drivers.toml_schema`). Device profile names (``"oriental-az"``)
are resolved against the ``configs/profiles`` directory found next to the package source
(``Path(goniolab.__file__).parents[1] / "configs"``) or, in an installed wheel,
``goniolab/_configs``; relative profile paths are tried next to the config file first.
Each profile is loaded once at config time so that a bad profile is reported against the
config key that names it.

Whatever would only fail at run time is refused at load:

* numbers are strict: TOML ``true`` is not 1 and ``1.5`` is not an integer (an integer is
  accepted where a float is expected);
* safety limits have a floor: ``min_separation_deg`` >= :data:`MIN_SEPARATION_FLOOR_DEG`
  (0 would switch the arm interlock off) and >= half the sum of the lamp and detector
  cones (closer, the detector would look into the lamp); the default arm limits, their
  sanity and that floor are those of :mod:`drivers.arm_limits`, which the drivers check too;
* every register value derived from an arm's settings fits its register with the arm's
  profile: positions ``limit_deg x steps_per_deg x gear_ratio`` in the int32 position
  register, speed and acceleration counts in theirs (int32, or 16 bits for a
  ``command-opcode`` drive), one step no coarser than ``stall_tolerance_deg``;
* homing can be planned from the park position (:func:`drivers.goniometer.plan_homing`:
  one arm must be able to stand clear of the other's home within its limits);
* ``spectro.exposure_us`` lies in the range of the spectro's profile;
* a file nested too deeply for the TOML parser is one error, not a RecursionError.

The package's modules: :mod:`goniolab.config.sections` (the pydantic models),
:mod:`goniolab.config.checks` (checks across keys and against the device profiles),
:mod:`goniolab.config.loader` (reading a file) and :mod:`goniolab.config.alignment_state`
(the alignment a scan found). Import from ``goniolab.config``.
"""

from __future__ import annotations

from drivers.arm_limits import MIN_SEPARATION_FLOOR_DEG
from goniolab.config.alignment_state import (
    alignment_state_path,
    write_alignment,
    write_alignment_state,
)
from goniolab.config.checks import INT32_MAX
from goniolab.config.loader import (
    configs_dir,
    load_lab_config,
    resolve_profile,
)
from goniolab.config.sections import (
    STALL_TOLERANCE_MAX_DEG,
    AlignmentConfig,
    AxisConfig,
    ColourConfig,
    FaultsConfig,
    GlossmeterConfig,
    GoniometerConfig,
    LabConfig,
    LabSection,
    ParkConfig,
    RunSection,
    SampleConfig,
    SimConfig,
    SpectroConfig,
    TwinConfig,
)
from goniolab.errors import ConfigError

__all__ = [
    "INT32_MAX",
    "MIN_SEPARATION_FLOOR_DEG",
    "STALL_TOLERANCE_MAX_DEG",
    "AlignmentConfig",
    "AxisConfig",
    "ColourConfig",
    "ConfigError",
    "FaultsConfig",
    "GlossmeterConfig",
    "GoniometerConfig",
    "LabConfig",
    "LabSection",
    "ParkConfig",
    "RunSection",
    "SampleConfig",
    "SimConfig",
    "SpectroConfig",
    "TwinConfig",
    "alignment_state_path",
    "configs_dir",
    "load_lab_config",
    "resolve_profile",
    "write_alignment",
    "write_alignment_state",
]

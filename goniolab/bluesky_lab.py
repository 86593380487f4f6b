"""bluesky / ophyd-async face of the lab (extra ``goniolab[bluesky]``).

ophyd-async devices built on the same drivers as the CLI and the TUI (any lab a config
describes: real controllers, the wire sim, or the in-process twin):

- :class:`GonioArm` -- one arm of the two-arm goniometer as a bluesky ``Movable``
  (``set(angle_deg)`` returns an ``AsyncStatus``): the move goes through
  :meth:`drivers.goniometer.TwoArmGoniometer.move_to`, so the arm limits and the two-arm
  separation interlock refuse an unsafe target (the status fails, nothing moves);
  ``readback_deg`` is the hinted reading, the limits are configuration signals.
- :class:`Goniometer` -- both arms as one ``Movable``: ``set((theta_i, theta_r))`` moves to a
  geometry in the safe order of :meth:`~drivers.goniometer.TwoArmGoniometer.move_to`. Every
  move of either device holds the goniometer for its whole travel, so ``bps.mv(lamp, a,
  detector, b)`` runs the two moves one after the other, each checked against the other
  arm's real position.
- :class:`Spectro` -- the spectro-colorimeter as a triggerable detector: ``luminance_pct``
  (hinted), the ``spectrum_pct`` array and CIE ``L_star``, ``a_star``, ``b_star`` computed
  as the store computes them (the config's ``[colour]``, the reflectance factor through the
  detector cone at the reading's angle, ASTM E308); ``wavelengths_nm``, ``exposure_us`` and
  ``colour_settings`` are configuration.
- :class:`Glossmeter` -- ``g20_gu``, ``g60_gu``, ``g85_gu`` (ISO 2813).

:func:`connect_lab` opens the lab in the RunEngine's event loop (where ophyd-async devices
live) and homes the arms; :func:`inplane_scan` is the in-plane BRDF scan as a bluesky plan
(lamp to theta_i, then the detector over theta_r, ``repeats`` readings per geometry, one
event each). Like ophyd-async's own ``StandardReadable`` devices (``sim/_motor.py``), the
devices are defined by their signals; the motion itself is the drivers' (trapezoid moves in
the twin).

Example
-------
>>> from bluesky import RunEngine
>>> from goniolab.bluesky_lab import connect_lab, inplane_scan
>>> RE = RunEngine()
>>> lab = connect_lab("configs/lab-sim.toml", time_scale=0)
>>> RE(inplane_scan(lab, theta_i_deg=45, theta_r_deg=[40, 45, 50], repeats=2))
>>> lab.close()
"""

from __future__ import annotations

import functools
import json
import logging
import math
import uuid
from collections.abc import Awaitable, Callable, Generator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from goniolab.errors import UserError
from goniolab.scan.plans import DEFAULT_REPEATS

if TYPE_CHECKING:  # pragma: no cover - typing only
    from goniolab.scan.colour import PointColour

_log = logging.getLogger(__name__)

try:
    from bluesky import plan_stubs as bps
    from bluesky import preprocessors as bpp
    from bluesky.run_engine import call_in_bluesky_event_loop
    from ophyd_async.core import (
        Array1D,
        AsyncStatus,
        StandardReadable,
        soft_signal_r_and_setter,
    )
    from ophyd_async.core import StandardReadableFormat as Format
except ImportError as _exc:  # pragma: no cover - depends on the installed extras
    raise UserError(
        f"the bluesky devices need the extra: pip install 'goniolab[bluesky]' ({_exc})"
    ) from None

__all__ = [
    "Glossmeter",
    "GonioArm",
    "Goniometer",
    "LabDevices",
    "Spectro",
    "connect_lab",
    "inplane_scan",
]

#: Timeout of one arm move, seconds (the config's ``move_timeout_s`` when known).
DEFAULT_MOVE_TIMEOUT_S = 60.0


def lab_of_spectrum(
    wavelengths_nm: ArrayLike,
    values_pct: ArrayLike,
    *,
    theta_r_deg: float,
    colour: PointColour | None = None,
) -> tuple[float, float, float]:
    """CIE L*, a*, b* of one spectro reading, through the pipeline the store's colour takes.

    The spectrum (% of the instrument's reference) becomes a reflectance factor through the
    detector cone at ``theta_r_deg`` with the lab's ``[colour]`` settings (illuminant,
    observer, method, scale: :class:`goniolab.scan.colour.PointColour`, the runner's own)
    and is integrated per ASTM E308. Issue 22.9: the bluesky face integrated the raw % as
    if it were a reflectance factor, with fixed D65 / 10 deg, and disagreed with the store
    (L* 0.31 against 46.5 at theta_r 35 deg).

    Returns NaNs, and logs why, when the spectrum gives no colour (wrong grid, NaN,
    negative beyond the noise floor), as the runner stores such a reading without colour.
    """
    from goniolab.colour.spectra import ColourError
    from goniolab.scan.colour import PointColour

    pc = colour if colour is not None else PointColour()
    try:
        c = pc.measured(
            np.asarray(wavelengths_nm, dtype=np.float64).tolist(),
            np.asarray(values_pct, dtype=np.float64).tolist(),
            float(theta_r_deg),
        )
    except (ColourError, ValueError) as exc:
        _log.warning("spectro at theta_r %.3f deg: no colour: %s", theta_r_deg, exc)
        return (math.nan, math.nan, math.nan)
    return (float(c.L), float(c.a), float(c.b))


class GonioArm(StandardReadable):
    """One arm (``"lamp"`` = theta_i or ``"detector"`` = theta_r) of a two-arm goniometer.

    Parameters
    ----------
    goniometer
        A :class:`drivers.goniometer.TwoArmGoniometer` (limits and interlock live there).
    which
        ``"lamp"`` or ``"detector"``.
    move_timeout_s
        Timeout of each move.
    """

    def __init__(
        self,
        goniometer: Any,
        which: str,
        *,
        move_timeout_s: float = DEFAULT_MOVE_TIMEOUT_S,
        name: str = "",
    ) -> None:
        if which not in ("lamp", "detector"):
            raise ValueError(f"which must be 'lamp' or 'detector', got {which!r}")
        self._gonio = goniometer
        self._which = which
        self._timeout_s = float(move_timeout_s)
        axis = goniometer.lamp if which == "lamp" else goniometer.detector
        lo, hi = axis.limits_deg
        with self.add_children_as_readables(Format.HINTED_SIGNAL):
            self.readback_deg, self._set_readback = soft_signal_r_and_setter(
                float, math.nan, units="deg"
            )
        with self.add_children_as_readables(Format.CONFIG_SIGNAL):
            self.low_limit_deg, _ = soft_signal_r_and_setter(float, float(lo), units="deg")
            self.high_limit_deg, _ = soft_signal_r_and_setter(float, float(hi), units="deg")
            self.min_separation_deg, _ = soft_signal_r_and_setter(
                float, float(goniometer.min_separation_deg), units="deg"
            )
        super().__init__(name=name)

    async def refresh(self) -> float:
        """Read the arm's position from the controller into ``readback_deg``."""
        ti, tr = await self._gonio.positions_deg()
        value = float(ti if self._which == "lamp" else tr)
        self._set_readback(value)
        return value

    @AsyncStatus.wrap
    async def set(self, value: float) -> None:
        """Move this arm to ``value`` deg, the other arm staying where it is.

        The goniometer reserves both arms for the move and checks the arm limits and the
        separation interlock against the other arm's position read under that reservation
        (:meth:`drivers.goniometer.TwoArmGoniometer.move_arm`): when bluesky sets both
        arms at once (``bps.mv(lamp, a, detector, b)``), the moves run one after the other
        and the second is checked against where the first really left its arm. An unsafe
        target fails the status (``LimitError`` / ``InterlockError``) and that arm does not
        move. To move both arms to a geometry in a safe order, set :class:`Goniometer`.
        """
        reached = await self._gonio.move_arm(self._which, float(value), self._timeout_s)
        self._set_readback(float(reached[0] if self._which == "lamp" else reached[1]))

    async def stop(self, success: bool = True) -> None:
        """Stop both arms (bluesky calls this on pause and abort)."""
        await self._gonio.stop()


class Goniometer(StandardReadable):
    """Both arms as one bluesky ``Movable``: ``set((theta_i_deg, theta_r_deg))`` moves to the
    geometry through :meth:`drivers.goniometer.TwoArmGoniometer.move_to` (limits, the
    separation interlock and the safe order of the two arms' moves), so a plan that changes
    both angles at once never brings the arms closer than their minimum on the way.

    ``theta_i_deg`` and ``theta_r_deg`` are the hinted readbacks.
    """

    def __init__(
        self,
        goniometer: Any,
        *,
        move_timeout_s: float = DEFAULT_MOVE_TIMEOUT_S,
        name: str = "",
    ) -> None:
        self._gonio = goniometer
        self._timeout_s = float(move_timeout_s)
        with self.add_children_as_readables(Format.HINTED_SIGNAL):
            self.theta_i_deg, self._set_ti = soft_signal_r_and_setter(float, math.nan, units="deg")
            self.theta_r_deg, self._set_tr = soft_signal_r_and_setter(float, math.nan, units="deg")
        with self.add_children_as_readables(Format.CONFIG_SIGNAL):
            self.min_separation_deg, _ = soft_signal_r_and_setter(
                float, float(goniometer.min_separation_deg), units="deg"
            )
        super().__init__(name=name)

    async def refresh(self) -> tuple[float, float]:
        """Read both arms' positions into the readbacks."""
        ti, tr = await self._gonio.positions_deg()
        self._set_ti(float(ti))
        self._set_tr(float(tr))
        return float(ti), float(tr)

    @AsyncStatus.wrap
    async def set(self, value: Sequence[float]) -> None:
        """Move to ``(theta_i_deg, theta_r_deg)``; an unsafe geometry fails the status and
        nothing moves."""
        if len(value) != 2:
            raise ValueError(f"goniometer: set takes (theta_i_deg, theta_r_deg), got {value!r}")
        reached = await self._gonio.move_to(float(value[0]), float(value[1]), self._timeout_s)
        self._set_ti(float(reached[0]))
        self._set_tr(float(reached[1]))

    async def stop(self, success: bool = True) -> None:
        """Stop both arms (bluesky calls this on pause and abort)."""
        await self._gonio.stop()


class Spectro(StandardReadable):
    """The spectro-colorimeter as a triggerable detector (one reading per trigger)."""

    def __init__(
        self,
        spectro: Any,
        *,
        exposure_us: int = 10000,
        colour: PointColour | None = None,
        theta_r_deg: Callable[[], Awaitable[float]] | None = None,
        name: str = "",
    ) -> None:
        from goniolab.scan.colour import PointColour

        self._spectro = spectro
        # the colour of a reading as the store computes it: the lab's [colour] settings and
        # the detector angle at the reading (lab_of_spectrum)
        self._colour = colour if colour is not None else PointColour()
        self._theta_r_deg = theta_r_deg
        with self.add_children_as_readables(Format.HINTED_SIGNAL):
            self.luminance_pct, self._set_luminance = soft_signal_r_and_setter(
                float, math.nan, units="%"
            )
        with self.add_children_as_readables():
            self.spectrum_pct, self._set_spectrum = soft_signal_r_and_setter(
                Array1D[np.float64], units="%"
            )
            self.L_star, self._set_L = soft_signal_r_and_setter(float, math.nan)
            self.a_star, self._set_a = soft_signal_r_and_setter(float, math.nan)
            self.b_star, self._set_b = soft_signal_r_and_setter(float, math.nan)
        with self.add_children_as_readables(Format.CONFIG_SIGNAL):
            self.wavelengths_nm, self._set_wavelengths = soft_signal_r_and_setter(
                Array1D[np.float64], units="nm"
            )
            self.exposure_us, self._set_exposure = soft_signal_r_and_setter(
                int, int(exposure_us), units="us"
            )
            self.colour_settings, _ = soft_signal_r_and_setter(
                str, json.dumps(self._colour.describe(), sort_keys=True)
            )
        super().__init__(name=name)

    @AsyncStatus.wrap
    async def trigger(self) -> None:
        """Take one reading and publish it on the signals."""
        reading = await self._spectro.measure()
        wl = np.asarray(reading.wavelengths_nm, dtype=np.float64)
        values = np.asarray(reading.values, dtype=np.float64)
        self._set_wavelengths(wl)
        self._set_spectrum(values)
        self._set_exposure(int(reading.exposure_us))
        self._set_luminance(float(reading.luminance_pct))
        theta_r = math.nan if self._theta_r_deg is None else await self._theta_r_deg()
        L, a, b = lab_of_spectrum(wl, values, theta_r_deg=theta_r, colour=self._colour)
        self._set_L(L)
        self._set_a(a)
        self._set_b(b)


class Glossmeter(StandardReadable):
    """The glossmeter as a triggerable detector: G20, G60, G85 in GU (ISO 2813)."""

    def __init__(self, glossmeter: Any, *, name: str = "") -> None:
        self._gloss = glossmeter
        with self.add_children_as_readables(Format.HINTED_SIGNAL):
            self.g20_gu, self._set_20 = soft_signal_r_and_setter(float, math.nan, units="GU")
            self.g60_gu, self._set_60 = soft_signal_r_and_setter(float, math.nan, units="GU")
            self.g85_gu, self._set_85 = soft_signal_r_and_setter(float, math.nan, units="GU")
        super().__init__(name=name)

    @AsyncStatus.wrap
    async def trigger(self) -> None:
        """Take one 20/60/85 deg reading (a geometry the meter does not report is NaN)."""
        reading = await self._gloss.measure()
        for angle, setter in ((20, self._set_20), (60, self._set_60), (85, self._set_85)):
            v = reading.values_gu.get(angle)
            setter(math.nan if v is None else float(v))


@dataclass
class LabDevices:
    """The devices of one open lab (:func:`connect_lab`); ``close()`` parks and releases."""

    lab: Any
    lamp: GonioArm
    detector: GonioArm
    spectro: Spectro
    goniometer: Goniometer
    glossmeter: Glossmeter | None
    sample: str
    #: closes the lab (:func:`goniolab.app.lab_scan.open_lab`)
    stack: Any = None

    def close(self) -> None:
        """Park the arms and release the instruments (in the RunEngine's loop)."""

        async def _close() -> None:
            try:
                g = self.lab.config.goniometer
                await self.lab.goniometer.park(g.move_timeout_s)
            finally:
                if self.stack is not None:
                    await self.stack.aclose()
                else:
                    await self.lab.__aexit__(None, None, None)

        call_in_bluesky_event_loop(_close())


async def _detector_deg(gonio: Any) -> float:
    """The detector arm's angle now (the geometry of a spectro reading)."""
    return float((await gonio.positions_deg())[1])


def connect_lab(
    config: str | Path, *, sample: str | None = None, time_scale: float | None = None
) -> LabDevices:
    """Open the lab of ``config`` in the bluesky event loop, home the arms, build the devices.

    A :class:`bluesky.RunEngine` must exist (it owns the loop the devices live in).
    """
    from contextlib import AsyncExitStack

    from goniolab.app.lab_scan import home_arms, open_lab
    from goniolab.app.lab_setup import load_config
    from goniolab.scan.colour import PointColour

    cfg = load_config(config)

    async def _open() -> LabDevices:
        stack = AsyncExitStack()
        lab = await stack.enter_async_context(
            open_lab(cfg, sample=sample or "", time_scale=time_scale)
        )
        try:
            c = lab.config
            gonio = lab.goniometer
            await home_arms(lab)
            timeout = c.goniometer.move_timeout_s
            devices = LabDevices(
                lab=lab,
                lamp=GonioArm(gonio, "lamp", move_timeout_s=timeout, name="lamp"),
                detector=GonioArm(gonio, "detector", move_timeout_s=timeout, name="detector"),
                spectro=Spectro(
                    lab.spectro,
                    exposure_us=c.spectro.exposure_us,
                    colour=PointColour.from_config(c),
                    theta_r_deg=functools.partial(_detector_deg, gonio),
                    name="spectro",
                ),
                goniometer=Goniometer(gonio, move_timeout_s=timeout, name="goniometer"),
                glossmeter=None
                if getattr(lab, "glossmeter", None) is None
                else Glossmeter(lab.glossmeter, name="glossmeter"),
                sample=c.sample.map,
                stack=stack,
            )
            for dev in (
                devices.lamp,
                devices.detector,
                devices.goniometer,
                devices.spectro,
                devices.glossmeter,
            ):
                if dev is not None:
                    await dev.connect()
            await devices.lamp.refresh()
            await devices.detector.refresh()
            await devices.goniometer.refresh()
            await lab.spectro.set_exposure_us(c.spectro.exposure_us)
            return devices
        except BaseException:
            await stack.aclose()
            raise

    result: LabDevices = call_in_bluesky_event_loop(_open())
    return result


def inplane_scan(
    lab: LabDevices,
    *,
    theta_i_deg: float,
    theta_r_deg: Sequence[float],
    repeats: int = DEFAULT_REPEATS,
    md: dict[str, Any] | None = None,
) -> Generator[Any, Any, str]:
    """The in-plane BRDF scan as a bluesky plan.

    Moves the lamp to ``theta_i_deg``, then for each detector angle moves the detector and
    takes ``repeats`` readings of the spectro (one event each, with both arms' readbacks).
    The start document carries the plan (``plan_name = "goniolab_inplane_scan"``, the
    angles, the sample) so that a bluesky-side analysis finds the geometry, and the run's
    identity as goniolab stores it: ``run_uuid`` (a UUID 4), ``operator``, ``sample_id``,
    ``notes`` and ``tags`` (from the config's ``[run]`` table; ``md`` overrides them).

    The plan is the one ``goniolab scan`` builds (:func:`goniolab.app.lab_setup.brdf_plan`),
    read in the order its runner reads it, and the session's dry run
    (:func:`goniolab.app.lab_scan.check_plan`) checks every geometry and the park position
    before the run opens: an unsafe plan moves nothing.

    Returns
    -------
    str
        The run's uid.

    Raises
    ------
    goniolab.errors.UserError
        An angle list or repeat count that is no plan, or a plan the arms cannot run.
    """
    from goniolab.app.lab_scan import check_plan
    from goniolab.app.lab_setup import brdf_plan

    config = lab.lab.config
    # the plan the CLI, the API and the TUI build, at the spectro's configured exposure
    plan = brdf_plan(
        config, sample=lab.sample, theta_i_deg=theta_i_deg,
        theta_r_deg=[float(t) for t in theta_r_deg], repeats=repeats, auto_exposure=False,
        what="inplane_scan", angles_option="theta_r_deg",
    )  # fmt: skip
    angles = list(plan.theta_r_deg)
    detectors = [lab.spectro]
    run_cfg = config.run
    identity = {  # the run identity a stored run has (issue 22.4): UUID, who, what sample
        "run_uuid": str(uuid.uuid4()),
        "operator": getattr(run_cfg, "operator", ""),
        "sample_id": getattr(run_cfg, "sample_id", ""),
        "notes": getattr(run_cfg, "notes", ""),
        "tags": list(getattr(run_cfg, "tags", ())),
    }
    metadata = {
        **identity,
        "plan_name": "goniolab_inplane_scan",
        "plan_args": {
            "theta_i_deg": plan.theta_i_deg,
            "theta_r_deg": angles,
            "repeats": plan.repeats,
        },
        "sample": lab.sample,
        "detectors": [d.name for d in detectors],
        "motors": [lab.lamp.name, lab.detector.name],
        "num_points": len(plan.points()),
        "hints": {"dimensions": [([lab.detector.readback_deg.name], "primary")]},
        **(md or {}),
    }

    @bpp.stage_decorator([*detectors, lab.lamp, lab.detector])
    @bpp.run_decorator(md=metadata)
    def inner() -> Generator[Any, Any, None]:
        # the readings in the order the session's runner takes them (plan.points())
        at: tuple[float, float] | None = None
        for pt in plan.points():
            if at is None or pt.theta_i_deg != at[0]:
                yield from bps.mv(lab.lamp, pt.theta_i_deg)
            if at is None or pt.theta_r_deg != at[1]:
                yield from bps.mv(lab.detector, pt.theta_r_deg)
            at = (pt.theta_i_deg, pt.theta_r_deg)
            yield from bps.trigger_and_read([*detectors, lab.lamp, lab.detector])

    # the session's dry run, in the RunEngine's loop, before any document or motion: an
    # unsafe plan is refused with the CLI's words (UserError), nothing moves
    (checked,) = yield from bps.wait_for([lambda: check_plan(lab.lab, plan, what="inplane_scan")])
    checked.result()
    uid: str = yield from inner()  # run_decorator returns the run's uid
    return uid

"""The simulated lab on the wire: the same simulated instruments as :mod:`sim.instruments`,
reachable the way real ones are (Modbus servers, serial ptys), so the real drivers in
:mod:`drivers` are tested end to end. :mod:`~sim.wire.modbus` (the arms),
:mod:`~sim.wire.serial` (spectro and glossmeter), :mod:`~sim.wire.lab_server` (all of them).
"""

from sim.wire.lab_server import SimLabServer
from sim.wire.modbus import ModbusAxisServer, WireAxis
from sim.wire.serial import StilPtyDevice, ZgmPtyDevice

__all__ = ["ModbusAxisServer", "SimLabServer", "StilPtyDevice", "WireAxis", "ZgmPtyDevice"]

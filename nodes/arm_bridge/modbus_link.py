"""The bridge's Modbus TCP backend (pymodbus async client) for the register map of docs/register_map.md.

For controllers and PLC gateways that expose Modbus TCP (and the Modbus twin). Each cycle: one FC04 read of
the input registers (state, status, fault; decoded by :mod:`messages.registers`), one FC16 write of the
watchdog counter + the six joint targets (registers 1..13, applied atomically), and, when the state asks for
it, an FC06 COMMAND write after the cycle:

* not enabled → restart the stream at the measured joints (no jump after a reconnect, a fault or an
  e-stop) and, unless faulted, write COMMAND = ENABLE;
* watchdog fault → report ``fault:watchdog``; with ``auto_reset`` write RESET | ENABLE (a RESET edge: the
  controller latches the fault until one comes, sending targets and counter again does not clear it);
* e-stop → report ``fault:estop`` and leave it to the operator: only the controller's local reset clears
  it (a RESET over Modbus does not), after which the controller is not enabled and the bridge enables it.

A refresh may write the targets a second time within one period (the controller latches the registers at its
own period), with the same watchdog value.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable

import numpy as np
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException

from flexsheet.arm.stream import LinkError, Verdict
from flexsheet.arm.tracking import BridgeStatus
from messages import registers as reg

__all__ = ["ModbusLink"]

_NET_ERRORS = (TimeoutError, ModbusException, OSError, ValueError)


class ModbusLink:
    """:class:`~flexsheet.arm.stream.ControllerLink` over Modbus TCP.

    ``host``/``port`` of the controller, ``device_id`` (Modbus unit id), ``request_timeout`` s,
    ``auto_reset`` (reset watchdog faults automatically; never e-stops); ``client_factory``: pymodbus's
    ``AsyncModbusTcpClient``, or :class:`flexsheet.twin.loopback.LoopbackModbusClient` on a simulated clock.
    """

    name = "modbus"
    rewrite_ok = True

    def __init__(self, host: str, port: int, *, device_id: int = 1, request_timeout: float = 0.1,
                 auto_reset: bool = True, client_factory=AsyncModbusTcpClient) -> None:
        self.host, self.port, self.device_id = host, int(port), int(device_id)
        self.request_timeout = float(request_timeout)
        self.auto_reset = auto_reset
        self.client_factory = client_factory   # a simulated clock's in-process twin: flexsheet.twin.loopback
        self.client: AsyncModbusTcpClient | None = None
        self.connected = False
        self.on_ready: Callable[[], None] | None = None
        self.watchdog = 0
        self.cmd_written: int | None = None
        self.writes = 0
        self.refused_writes = 0
        self._pending_cmd: int | None = None
        self._seeded = False

    async def open(self) -> bool:
        """Connect the client (a fresh one each time); False if the controller cannot be reached."""
        self._close()
        client = self.client_factory(self.host, port=self.port, timeout=self.request_timeout, retries=0,
                                     reconnect_delay=0, reconnect_delay_max=0)
        try:
            ok = await asyncio.wait_for(client.connect(), timeout=max(0.2, 2 * self.request_timeout))
        except (TimeoutError, OSError, ModbusException):
            ok = False
        if not ok:
            client.close()
            return False
        self.client = client
        self.connected = True
        self.cmd_written = None
        self._seeded = False
        return True

    def _close(self) -> None:
        if self.client is not None:
            with contextlib.suppress(Exception):
                self.client.close()
        self.client = None
        self.connected = False

    async def read(self) -> reg.ControllerState:
        """FC04 read of the input image, decoded. Raises :class:`LinkError`."""
        if self.client is None:
            raise LinkError("not connected")
        try:
            rr = await self.client.read_input_registers(0, count=reg.IR_COUNT, device_id=self.device_id)
            if rr.isError():
                raise ModbusException(f"read refused: {rr}")
            return reg.decode_input(rr.registers)
        except _NET_ERRORS as exc:
            raise LinkError(f"{type(exc).__name__}: {exc}") from exc

    def supervise(self, st: reg.ControllerState) -> Verdict:
        """Enable / reset / e-stop handling (see module doc)."""
        reseed = None
        if not self._seeded:
            reseed = st.position
            self._seeded = True
        if st.fault == reg.FAULT_ESTOP or st.has(reg.ST_ESTOP):
            return Verdict(False, "fault:estop", st.position)
        if st.fault == reg.FAULT_WATCHDOG:
            if self.auto_reset:
                self._pending_cmd = reg.CMD_RESET | reg.CMD_ENABLE
            return Verdict(False, "fault:watchdog", st.position)
        if not st.has(reg.ST_ENABLED):
            self._pending_cmd = reg.CMD_ENABLE
            return Verdict(False, BridgeStatus.DISABLED, st.position)
        return Verdict(True, "", reseed)

    async def send(self, cmd: np.ndarray, rewrite: bool = False) -> bool:
        """One FC16 write of watchdog + targets (a rewrite keeps the watchdog value). Raises
        :class:`LinkError`."""
        if self.client is None:
            raise LinkError("not connected")
        if not rewrite:
            self.watchdog = (self.watchdog + 1) & 0xFFFF
        try:
            wr = await self.client.write_registers(reg.HR_WATCHDOG, [self.watchdog, *reg.encode_joints(cmd)],
                                                   device_id=self.device_id)
        except _NET_ERRORS as exc:
            raise LinkError(f"{type(exc).__name__}: {exc}") from exc
        self.writes += 1
        if wr.isError():
            self.refused_writes += 1
            return False
        return True

    async def keepalive(self) -> None:
        """Disabled: nothing is written (the read was the exchange)."""

    async def after_cycle(self) -> None:
        """Write COMMAND when the supervision asked for it (RESET acts on its rising edge)."""
        if self.client is None:
            return
        cmd = self._pending_cmd
        if cmd is None and self.cmd_written is not None and self.cmd_written & reg.CMD_RESET:
            cmd = reg.CMD_ENABLE   # drop the RESET bit so the next reset is an edge again
        if cmd is None:
            return
        if cmd & reg.CMD_RESET and self.cmd_written is not None and self.cmd_written & reg.CMD_RESET:
            cmd = cmd & ~reg.CMD_RESET   # RESET acts on its rising edge: clear it now, set it next cycle
        else:
            self._pending_cmd = None
        try:
            rr = await self.client.write_register(reg.HR_COMMAND, cmd, device_id=self.device_id)
        except _NET_ERRORS as exc:
            raise LinkError(f"{type(exc).__name__}: {exc}") from exc
        if rr.isError():
            raise LinkError(f"command refused: {rr}")
        self.cmd_written = cmd

    def ready_time(self) -> float | None:
        """Never early: Modbus cycles run on the bridge's own schedule."""
        return None

    def next_deadline(self, deadline: float, t_start: float, period: float) -> float:
        """Absolute schedule: ``deadline + period``."""
        return deadline + period

    async def close(self, end: bool = False) -> None:
        """Close the TCP connection (Modbus has no session to end)."""
        self._close()

    def counters(self) -> dict:
        """``writes``, ``refused_writes``, ``watchdog``."""
        return {"writes": self.writes, "refused_writes": self.refused_writes, "watchdog": self.watchdog}

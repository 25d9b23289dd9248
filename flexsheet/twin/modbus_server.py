"""The controller twin's Modbus TCP server (pymodbus) with the register map of docs/register_map.md, around
:class:`flexsheet.twin.controller.ControllerCore`; the ``arm_controller_sim`` node and ``flexsheet bench arm``
serve it.

The e-stop is cleared only by the twin's local reset (the operator's reset key at the controller), never over
Modbus: :meth:`ControllerTwin.local_reset`, or from a shell when the twin watches a ``reset_file``
(``touch FILE``: each change of its modification time is one reset press)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import time

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from flexsheet.runtime.clock import ticks
from flexsheet.twin.controller import ControllerCore, WriteRejected
from messages import registers as reg

__all__ = ["ControllerTwin"]

log = logging.getLogger(__name__)

RESET_POLL_S = 0.1      #: how often the reset file is looked at, s


class ControllerTwin:
    """Modbus TCP server around a :class:`ControllerCore`.

    ``core``: the controller logic (its clock is ``time.monotonic()``). ``host``/``port``: where to listen
    (port 0 picks a free port; :attr:`port` holds the bound one after :meth:`start`). ``reset_file``: a path
    whose modification time is watched (every ``RESET_POLL_S``); each change is one local reset (it need not
    exist at start; ``touch`` creates it).
    """

    def __init__(self, core: ControllerCore, host: str = "127.0.0.1", port: int = 0,
                 reset_file: str | os.PathLike | None = None) -> None:
        self.core = core
        self.host = host
        self.port = port
        self.reset_file = os.fspath(reset_file) if reset_file else None
        self.server: ModbusTcpServer | None = None
        self._task: asyncio.Task | None = None
        self._reset_mtime = self._mtime()
        self._reset_checked = 0.0

    def _mtime(self) -> float | None:
        if self.reset_file is None:
            return None
        try:
            return os.stat(self.reset_file).st_mtime_ns
        except OSError:
            return None

    def local_reset(self) -> bool:
        """The operator's reset at the controller: clears a latched e-stop or watchdog fault (the arm stays
        held until a client writes ENABLE). Returns True if a fault was cleared."""
        cleared = self.core.local_reset(time.monotonic())
        log.warning("controller twin: local reset (%s)", "fault cleared" if cleared else "no fault")
        return cleared

    def _poll_reset_file(self, now: float) -> None:
        if self.reset_file is None or now - self._reset_checked < RESET_POLL_S:
            return
        self._reset_checked = now
        m = self._mtime()
        if m is not None and m != self._reset_mtime:
            self._reset_mtime = m
            self.local_reset()

    async def _action(self, function_code, start_address, address, count, registers, set_values):
        now = time.monotonic()
        core = self.core
        core.advance(now)
        if function_code == 4:
            registers[0:reg.IR_COUNT] = core.input_registers(now)
        elif function_code == 3:
            registers[0:reg.HR_COUNT] = core.holding
        elif set_values is not None:
            try:
                core.write_holding(address, list(set_values), now)
            except WriteRejected as exc:
                return ExcCodes.ILLEGAL_ADDRESS if exc.code == reg.REJ_ADDRESS else ExcCodes.ILLEGAL_VALUE
        return None

    async def start(self) -> int:
        """Listen and start the servo task; returns the bound TCP port."""
        device = SimDevice(
            id=0,
            simdata=(
                [SimData(0, count=16, values=False, datatype=DataType.BITS)],
                [SimData(0, count=16, values=False, datatype=DataType.BITS)],
                [SimData(0, count=reg.HR_COUNT, values=0, datatype=DataType.REGISTERS)],
                [SimData(0, count=reg.IR_COUNT, values=0, datatype=DataType.REGISTERS)],
            ),
            action=self._action,
        )
        self.server = ModbusTcpServer(device, address=(self.host, self.port))
        await self.server.serve_forever(background=True)
        self.port = self.server.transport.sockets[0].getsockname()[1]
        self._task = asyncio.get_running_loop().create_task(self._run())
        return self.port

    async def _run(self) -> None:
        async for _ in ticks(self.core.period):
            now = time.monotonic()
            self.core.advance(now)
            self._poll_reset_file(now)

    async def stop(self) -> None:
        """Stop the servo task and close the server and its connections."""
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        if self.server is not None:
            await self.server.shutdown()
            self.server = None

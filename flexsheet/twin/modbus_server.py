"""The controller twin's Modbus TCP server (pymodbus) with the register map of docs/register_map.md, around
:class:`flexsheet.twin.controller.ControllerCore`; the ``arm_controller_sim`` node and ``flexsheet bench arm``
serve it."""

from __future__ import annotations

import asyncio
import time

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from flexsheet.runtime.node import ticks
from flexsheet.twin.controller import ControllerCore, WriteRejected
from messages import registers as reg

__all__ = ["ControllerTwin"]


class ControllerTwin:
    """Modbus TCP server around a :class:`ControllerCore`.

    ``core``: the controller logic (its clock is ``time.monotonic()``). ``host``/``port``: where to listen
    (port 0 picks a free port; :attr:`port` holds the bound one after :meth:`start`).
    """

    def __init__(self, core: ControllerCore, host: str = "127.0.0.1", port: int = 0) -> None:
        self.core = core
        self.host = host
        self.port = port
        self.server: ModbusTcpServer | None = None
        self._task: asyncio.Task | None = None

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
            self.core.advance(time.monotonic())

    async def stop(self) -> None:
        """Stop the servo task and close the server and its connections."""
        if self._task is not None:
            self._task.cancel()
            try:
                await self._task
            except asyncio.CancelledError:
                pass
            self._task = None
        if self.server is not None:
            await self.server.shutdown()
            self.server = None

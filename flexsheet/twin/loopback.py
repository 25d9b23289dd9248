"""The controller twins' registers reached in-process, for a graph on a simulated clock (``clock: sim``).

On the wall clock a bridge talks Modbus TCP to the controller twin's server
(:class:`flexsheet.twin.modbus_server.ControllerTwin`). On a simulated clock both run in one process and the
exchange must happen at a simulated instant, not when a socket delivers: the twin node :func:`register` s its
:class:`~flexsheet.twin.controller.ControllerCore` under its ``host:port`` with the clock it reads, and the
bridge's :class:`~nodes.arm_bridge.modbus_link.ModbusLink` uses :class:`LoopbackModbusClient` in place of
pymodbus's client: the same requests (FC04 read, FC16 / FC06 writes) go through the same core calls the
server makes, with the same refusals. Source: the server's request handler, ``ControllerTwin._action``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from flexsheet.twin.controller import ControllerCore, WriteRejected
from messages import registers as reg

__all__ = ["register", "unregister", "LoopbackModbusClient"]

_CORES: dict[tuple[str, int], tuple[ControllerCore, Callable[[], float]]] = {}


def register(host: str, port: int, core: ControllerCore, clock: Callable[[], float]) -> None:
    """Serve ``core`` at ``host:port`` to loopback clients; ``clock()`` gives the time of each request, s."""
    _CORES[(str(host), int(port))] = (core, clock)


def unregister(host: str, port: int) -> None:
    """Stop serving ``host:port`` (a client's next request fails as a dropped connection would)."""
    _CORES.pop((str(host), int(port)), None)


class _Reply:
    """A pymodbus-like response: ``registers`` and ``isError()``; ``exception_code`` when refused."""

    def __init__(self, registers: Sequence[int] = (), exception_code: int = 0) -> None:
        self.registers = list(registers)
        self.exception_code = exception_code

    def isError(self) -> bool:  # noqa: N802 - pymodbus's name
        return self.exception_code != 0

    def __repr__(self) -> str:
        return (f"ExceptionResponse(exception_code={self.exception_code})" if self.exception_code
                else "Response()")


class LoopbackModbusClient:
    """The subset of ``pymodbus.client.AsyncModbusTcpClient`` that the bridge's Modbus link uses, served by a
    :func:`register` ed core. Requests raise ``ConnectionError`` (an ``OSError``) when nothing serves the
    address, as a refused TCP connection does."""

    def __init__(self, host: str, port: int = 502, **_: object) -> None:
        self.key = (str(host), int(port))

    def _core(self) -> tuple[ControllerCore, float]:
        entry = _CORES.get(self.key)
        if entry is None:
            raise ConnectionError(f"no controller twin at {self.key[0]}:{self.key[1]}")
        core, clock = entry
        now = clock()
        core.advance(now)
        return core, now

    async def connect(self) -> bool:
        return self.key in _CORES

    def close(self) -> None:
        """Nothing to close."""

    async def read_input_registers(self, address: int, count: int = 1, device_id: int = 1) -> _Reply:
        core, now = self._core()
        regs = core.input_registers(now)
        if address < 0 or address + count > len(regs):
            return _Reply(exception_code=2)
        return _Reply(regs[address:address + count])

    async def _write(self, address: int, values: list[int]) -> _Reply:
        core, now = self._core()
        try:
            core.write_holding(address, values, now)
        except WriteRejected as exc:
            return _Reply(exception_code=2 if exc.code == reg.REJ_ADDRESS else 3)
        return _Reply(values)

    async def write_registers(self, address: int, values: Sequence[int], device_id: int = 1) -> _Reply:
        return await self._write(address, [int(v) for v in values])

    async def write_register(self, address: int, value: int, device_id: int = 1) -> _Reply:
        return await self._write(address, [int(value)])

"""The service socket's answers (flexsheet/runtime/services.py): every bad request gets one error line naming
what was wrong, a handler that raises is the caller's error, and a real round trip over the socket works."""

import asyncio

import msgpack
import pytest

from flexsheet.runtime.services import ServiceError, ServiceServer, call_async


def _answer(srv: ServiceServer, payload: bytes) -> dict:
    return asyncio.run(srv._answer(payload))


def test_bad_requests_are_answered_with_the_reason_and_the_server_goes_on():
    srv = ServiceServer("tcp://127.0.0.1")
    try:
        srv.add("echo", lambda a: a, "echo its args")
        srv.add("boom", lambda a: 1 / 0, "raises")
        pk = lambda o: msgpack.packb(o, use_bin_type=True)          # noqa: E731
        cases = [(b"\xc1\xff", "not msgpack"), (pk([1, 2]), "must be a map with 'service'"),
                 (pk({"service": "nope"}), "no service 'nope'; services: boom, echo, list"),
                 (pk({"service": "echo", "args": [1]}), "'args' must be a map, got list"),
                 (pk({"service": "boom"}), "ZeroDivisionError: division by zero"),
                 (b"x" * ((1 << 20) + 1), "exceeds")]
        for payload, why in cases:
            r = _answer(srv, payload)
            assert r["ok"] is False and why in r["error"], (why, r)
        assert _answer(srv, pk({"service": "echo", "args": {"a": 1}})) == {"ok": True, "result": {"a": 1}}
        assert srv.errors == len(cases) and srv.calls == len(cases) + 1
    finally:
        srv.close()


def test_a_call_over_the_socket_and_a_silent_endpoint():
    async def main():
        srv = ServiceServer("tcp://127.0.0.1")
        srv.add("add", lambda a: a["x"] + a["y"], "x + y")
        srv.start()
        try:
            assert await call_async(srv.endpoint, "add", {"x": 2, "y": 3}) == 5
            with pytest.raises(ServiceError, match="KeyError"):
                await call_async(srv.endpoint, "add", {"x": 2})
            assert "add" in await call_async(srv.endpoint, "list")
        finally:
            srv.close()
        with pytest.raises(ServiceError, match="no reply from tcp://127.0.0.1:9 to 'list' within 0.3 s"):
            await call_async("tcp://127.0.0.1:9", "list", timeout=0.3)
    asyncio.run(main())

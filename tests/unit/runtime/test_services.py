"""The service socket's answers (flexsheet/runtime/services.py): every bad request gets one error line naming
what was wrong, a handler that raises is the caller's error, and a real round trip over the socket works."""

import asyncio

import msgpack
import pytest

from flexsheet.runtime.services import ServiceError, ServiceServer, call_async


def _answer(srv: ServiceServer, payload: bytes, caller: str = "") -> dict:
    return asyncio.run(srv._answer(payload, caller))


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


def test_commanding_services_take_only_the_hosts_tools():
    """A commanding service (param/set, graph/*, the arm's moves): with CURVE only a host's key may call it,
    never another node's; without CURVE only on a loopback graph. Reading services stay open to every
    identity."""
    import zmq

    from flexsheet.runtime.zmq.curve import CurveConfig

    pk = lambda o: msgpack.packb(o, use_bin_type=True)          # noqa: E731
    (host_pub, _), (node_pub, _) = zmq.curve_keypair(), zmq.curve_keypair()
    me_pub, me_sec = zmq.curve_keypair()
    curve = CurveConfig(public_key=me_pub, secret_key=me_sec, allowed_clients=[host_pub, node_pub],
                        tool_keys=[host_pub])
    srv = ServiceServer("tcp://127.0.0.1", curve)
    try:
        srv.add("move", lambda a: "moved", "moves", commanding=True)
        srv.add("read", lambda a: 1, "reads")
        refused = _answer(srv, pk({"service": "move"}), node_pub.decode())
        assert refused["ok"] is False and "only a host's key" in refused["error"]
        assert _answer(srv, pk({"service": "move"}), host_pub.decode()) == {"ok": True, "result": "moved"}
        assert _answer(srv, pk({"service": "read"}), node_pub.decode()) == {"ok": True, "result": 1}
    finally:
        srv.close()
    for address, ok in (("tcp://127.0.0.1", True), ("tcp://0.0.0.0", False)):
        srv = ServiceServer(address)
        try:
            srv.add("move", lambda a: "moved", "moves", commanding=True)
            r = _answer(srv, pk({"service": "move"}))
            assert r["ok"] is ok and (ok or "needs CURVE" in r["error"]), (address, r)
        finally:
            srv.close()


def test_a_result_msgpack_cannot_carry_is_an_error_reply_and_the_server_goes_on():
    import numpy as np

    async def main():
        srv = ServiceServer("tcp://127.0.0.1")
        srv.add("bad", lambda a: np.float32(1.5), "returns a numpy scalar")
        srv.start()
        try:
            with pytest.raises(ServiceError, match="the result cannot be sent"):
                await call_async(srv.endpoint, "bad")
            assert "bad" in await call_async(srv.endpoint, "list")     # still serving
        finally:
            srv.close()
    asyncio.run(main())

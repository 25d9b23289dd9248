"""Services: request/reply calls into a running node, as ROS 2 services (and its run-time parameters).

Every node binds one ZeroMQ ROUTER socket (:class:`ServiceServer`) on its publisher's address, on a port the
OS picks, and names it in its heartbeat (``Heartbeat.service_endpoint``), so a tool finds it from
``/diagnostics``. A request is one msgpack map ``{"service": NAME, "args": {...}}``; the reply is
``{"ok": true, "result": ...}`` or ``{"ok": false, "error": "one line"}``. A bad request (not msgpack, unknown
service, wrong arguments, a handler that raises) gets an error reply naming what was wrong; it never stops the
node. With CURVE the socket is a CURVE server with the node's key, behind the same ZAP allow-list as its
publisher. The sockets are :mod:`flexsheet.runtime.zmq.reqrep`'s (the package :mod:`flexsheet.runtime.zmq` is
the only code that talks to ZeroMQ).

Built in on every node: ``list`` (the services with one line each), ``param/list``, ``param/get``,
``param/set`` (:class:`ParamServices`: a param listed in the node's ``DYNAMIC_PARAMS`` may be set while it
runs, validated by its ``Params`` model; every other param is read-only at run time), ``clock/now`` and
``topic/pub`` (one encoded message delivered to the node's subscriptions: ``flexsheet topic pub``).

:func:`call` is the client: one request, one reply, within a timeout.
"""

from __future__ import annotations

import asyncio
import logging
import typing
from collections.abc import Callable
from typing import Any

import msgpack

from flexsheet.runtime.zmq.reqrep import ServiceSocket, request

__all__ = ["ServiceError", "ServiceServer", "ParamServices", "call", "topic_pub", "MAX_REQUEST_BYTES"]

log = logging.getLogger(__name__)

#: the largest request a node reads; a bigger one is answered with an error
MAX_REQUEST_BYTES = 1 << 20


class ServiceError(RuntimeError):
    """A call failed: no reply within the timeout, or the node answered with an error (its line)."""


def _jsonable(v: Any) -> Any:
    """Plain msgpack types for a param value (tuples → lists, paths and enums → str)."""
    if isinstance(v, (str, int, float, bool)) or v is None:
        return v
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if hasattr(v, "model_dump"):
        return _jsonable(v.model_dump())
    return str(v)


class ParamServices:
    """``param/list``, ``param/get``, ``param/set`` over ``node.params`` (a pydantic model). ``dynamic``: the
    names that may be set at run time; setting one validates the whole model with the new value (so a range or
    a cross-field check holds) and assigns ``node.params`` the new model, then calls ``node.on_params_set``
    with the names changed."""

    def __init__(self, node) -> None:
        self.node = node

    def _fields(self):
        return type(self.node.params).model_fields

    def list(self, args: dict) -> list[dict]:
        """Every param: name, type, default, value, description (with units), whether settable."""
        out = []
        dynamic = self.node.DYNAMIC_PARAMS
        for name, f in self._fields().items():
            default = None if f.is_required() else f.get_default(call_default_factory=True)
            out.append({"name": name, "type": _type_name(f.annotation), "default": _jsonable(default),
                        "value": _jsonable(getattr(self.node.params, name)),
                        "description": f.description or "", "dynamic": name in dynamic})
        return out

    def get(self, args: dict) -> Any:
        """``{"name": N}`` → the param's value."""
        name = _name_arg(args)
        if name not in self._fields():
            raise ValueError(f"no param {name!r}; params: {', '.join(self._fields())}")
        return _jsonable(getattr(self.node.params, name))

    def set(self, args: dict) -> Any:
        """``{"name": N, "value": V}`` → the value now in effect. Raises ``ValueError`` naming the param for
        an unknown or read-only param or a value its model refuses."""
        name = _name_arg(args)
        if "value" not in args:
            raise ValueError("param/set needs 'value'")
        if name not in self._fields():
            raise ValueError(f"no param {name!r}; params: {', '.join(self._fields())}")
        if name not in self.node.DYNAMIC_PARAMS:
            settable = ", ".join(sorted(self.node.DYNAMIC_PARAMS)) or "none"
            raise ValueError(f"param {name!r} is read-only at run time (set it in the launch file); "
                             f"settable here: {settable}")
        from pydantic import ValidationError

        data = self.node.params.model_dump()
        data[name] = args["value"]
        try:
            new = type(self.node.params).model_validate(data)
        except ValidationError as exc:
            err = exc.errors()[0]
            raise ValueError(f"param {name!r}: {err['msg']} (value {args['value']!r})") from None
        self.node.params = new
        self.node.on_params_set({name})
        return _jsonable(getattr(new, name))


def topic_pub(node: Any, args: dict) -> int:
    """The ``topic/pub`` service of ``node`` (on its loop): ``frames`` (a list of bytes, the wire encoding,
    the first frame the topic's name) go to the node's subscriptions of ``topic``, where they are decoded and
    validated like any message from the wire. Returns the number of subscriptions reached. Raises
    ``ValueError`` naming the field: a topic the node does not subscribe to, one the launch file guards
    (``security.publishers``), or frames that are not the topic's bytes. A tool reaches the graph by a call to
    each node's bound service socket, so the graph never connects to, nor disconnects from, a tool."""
    topic, frames = args.get("topic"), args.get("frames")
    if not isinstance(topic, str) or not topic:
        raise ValueError(f"topic must be a topic name, got {topic!r}")
    if not (isinstance(frames, list) and len(frames) >= 2 and all(isinstance(f, bytes) for f in frames)):
        raise ValueError(f"frames must be a list of at least 2 byte strings, got {type(frames).__name__}")
    if frames[0] != topic.encode():
        raise ValueError(f"frames[0] must be the topic {topic!r}, got {frames[0][:80]!r}")
    links = getattr(node.transport, "links", None)
    if links is None:
        links = getattr(getattr(node._bus, "sub", None), "links", None)
    if links is not None and topic.encode() in getattr(links, "guards", {}):
        raise ValueError(f"topic {topic!r} is guarded by the launch file (security.publishers)")
    subs = node._subs_b.get(frames[0])
    if not subs:
        raise ValueError(f"topic {topic!r}: this node does not subscribe to it")
    node._on_frames(frames)
    return len(subs)


def _type_name(t) -> str:
    origin = typing.get_origin(t)
    if origin is None:
        return getattr(t, "__name__", str(t))
    return str(t).replace("typing.", "")


def _name_arg(args: dict) -> str:
    name = args.get("name") if isinstance(args, dict) else None
    if not isinstance(name, str) or not name:
        raise ValueError(f"needs 'name' (a param name), got {name!r}")
    return name


class ServiceServer:
    """The node's service socket and its services (module doc): a
    :class:`~flexsheet.runtime.zmq.reqrep.ServiceSocket` on ``address`` ("tcp://127.0.0.1"), CURVE with the
    node's :class:`~flexsheet.runtime.zmq.curve.CurveConfig` ``curve``, on the node's ZeroMQ context
    ``ctx``."""

    def __init__(self, address: str, curve=None, ctx=None) -> None:
        self.sock = ServiceSocket(address, curve, ctx, MAX_REQUEST_BYTES)
        self.endpoint = self.sock.endpoint
        self.curve = curve
        host = address.removeprefix("tcp://")
        self.loopback = host.startswith("127.") or host in ("localhost", "[::1]")
        self.handlers: dict[str, tuple[Callable[[dict], Any], str]] = {}
        self.commanding: set[str] = set()
        self._task: asyncio.Task | None = None
        self.calls = 0
        self.errors = 0
        self.add("list", lambda args: {n: d for n, (_, d) in sorted(self.handlers.items())},
                 "the services of this node, one line each")

    def add(self, name: str, handler: Callable[[dict], Any], doc: str, commanding: bool = False) -> None:
        """Register ``handler(args) -> result`` (plain msgpack types; may be ``async``) as ``name``;
        ``commanding``: it changes what the node does (module doc: who may call it)."""
        self.handlers[name] = (handler, doc)
        if commanding:
            self.commanding.add(name)

    def _refusal(self, name: str, caller: str) -> str | None:
        """Why ``caller`` (a Z85 key, "" without CURVE) may not call commanding service ``name``, or None."""
        if name not in self.commanding:
            return None
        if self.curve is None:
            return None if self.loopback else (f"{name!r} commands the node: on a networked graph it needs "
                                               "CURVE (security.curve) and a host's key")
        if caller.encode() not in self.curve.tool_keys:
            return f"{name!r} commands the node: only a host's key (a tool run on a host) may call it"
        return None

    def start(self) -> None:
        """Serve on the running loop."""
        self._task = asyncio.get_running_loop().create_task(self._serve())

    async def _serve(self) -> None:
        while True:
            try:
                got = await self.sock.recv()
            except asyncio.CancelledError:
                return
            if got is None:
                return
            ident, payload, caller = got
            reply = await self._answer(payload, caller)
            try:
                packed = msgpack.packb(reply, use_bin_type=True)
            except (TypeError, ValueError, OverflowError) as exc:   # a result msgpack cannot carry
                self.errors += 1
                log.warning("service reply not serialisable: %s", exc)
                packed = msgpack.packb({"ok": False, "error": f"the result cannot be sent: {exc}"[:500]},
                                       use_bin_type=True)
            await self.sock.reply(ident, packed)

    async def _answer(self, payload: bytes, caller: str = "") -> dict:
        self.calls += 1
        try:
            if len(payload) > MAX_REQUEST_BYTES:
                raise ValueError(f"request of {len(payload)} bytes exceeds {MAX_REQUEST_BYTES}")
            try:
                req = msgpack.unpackb(payload, raw=False)
            except (ValueError, msgpack.UnpackException) as exc:
                raise ValueError(f"request is not msgpack: {exc}") from None
            if not isinstance(req, dict) or not isinstance(req.get("service"), str):
                raise ValueError("request must be a map with 'service' (a name) and 'args' (a map)")
            name, args = req["service"], req.get("args") or {}
            if not isinstance(args, dict):
                raise ValueError(f"'args' must be a map, got {type(args).__name__}")
            if name not in self.handlers:
                raise ValueError(f"no service {name!r}; services: {', '.join(sorted(self.handlers))}")
            refused = self._refusal(name, caller)
            if refused:
                raise ValueError(refused)
            result = self.handlers[name][0](args)
            if asyncio.iscoroutine(result):
                result = await result
            return {"ok": True, "result": result}
        except Exception as exc:        # noqa: BLE001 - every failure is the caller's answer, never the node's end
            self.errors += 1
            return {"ok": False, "error": " ".join(f"{type(exc).__name__}: {exc}".split())[:500]
                    if not isinstance(exc, ValueError) else " ".join(str(exc).split())[:500]}

    def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
        self.sock.close()


async def call_async(endpoint: str, service: str, args: dict | None = None, timeout: float = 2.0,
                     curve=None, server_key: bytes | None = None) -> Any:
    """One request to the service socket at ``endpoint``; the result. ``curve`` (the caller's keys) with
    ``server_key`` (the node's public key) for a CURVE graph. Raises :class:`ServiceError` with the node's
    error line, or on no reply within ``timeout`` s."""
    raw = await request(endpoint, msgpack.packb({"service": service, "args": args or {}}, use_bin_type=True),
                        timeout, curve, server_key)
    if raw is None:
        raise ServiceError(f"no reply from {endpoint} to {service!r} within {timeout:g} s")
    reply = msgpack.unpackb(raw, raw=False)
    if not reply.get("ok"):
        raise ServiceError(reply.get("error", "error"))
    return reply.get("result")


def call(endpoint: str, service: str, args: dict | None = None, timeout: float = 2.0, curve=None,
         server_key: bytes | None = None) -> Any:
    """:func:`call_async` from synchronous code."""
    return asyncio.run(call_async(endpoint, service, args, timeout, curve, server_key))

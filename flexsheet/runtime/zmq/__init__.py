"""The ZeroMQ transport: the only package that talks to ZeroMQ (pyzmq, imported absolutely as ``zmq``).

A transport moves encoded multipart frames (see :mod:`flexsheet.runtime.codec`) between nodes
(the interface: :class:`flexsheet.runtime.transport.Transport`):

* :class:`~flexsheet.runtime.zmq.transport.ZmqTransport` — brokerless. Each node binds **one** XPUB socket at
  its endpoint (from the launch file) and connects **one** SUB socket to every peer endpoint of the graph
  (plus one per set of publishers a guarded topic is restricted to,
  :class:`~flexsheet.runtime.zmq.subscriber.SubLinks`); SUB subscribes by topic name, so filtering happens at
  the publisher. XPUB sees each new subscription, which is how latched topics resend their last value to late
  joiners without any ``sleep()``. Readiness comes from the sockets' file descriptors through
  ``loop.add_reader`` and every ready message is drained with non-blocking ``recv`` — no ``zmq.asyncio``
  futures on the hot path (pyzmq's own ``zmq/asyncio.py`` allocates a future per receive, which is what
  doubles its latency).
* :class:`~flexsheet.runtime.zmq.xpub.XPub` — one bound XPUB socket, shared by ``ZmqTransport`` and the
  composable container (:mod:`flexsheet.runtime.container`): a send is thread-safe (one lock per socket, so a
  node's worker thread sends without waking the event loop), and the socket's subscriptions are tracked
  (``XPUB_VERBOSE``: every subscribe, and an unsubscribe when the last subscriber of a prefix leaves or
  disconnects), so a publisher knows whether anyone outside its process wants a topic (``XPub.wants``) and
  encodes only then.

Links heal (:class:`~flexsheet.runtime.zmq.linkwatch.LinkWatch`): libzmq gives up on a connection for good
after a protocol or handshake error (``session_base_t::engine_error``: a ``protocol_error`` terminates the
session, no reconnect), so one listener that speaks the wrong protocol on a dead node's port (not ZMTP, or
plain ZMTP against CURVE) cut that node off until its subscribers restarted. Every SUB socket's monitor is
watched; an endpoint whose session ended without a reconnect is connected again, with back-off, and refusals
are logged at most once per ``LinkWatch.LOG_EVERY_S`` per endpoint, with a count.

Memory (``XPub``): a publisher's queue per subscriber is bounded by bytes as well as by count: the send
high-water mark is lowered to ``budget_bytes`` / (largest message sent), so a subscriber that stops reading
costs at most about :data:`~flexsheet.runtime.zmq.xpub.PUB_QUEUE_BYTES` of the publisher's memory; a message
that a full subscriber queue could not take is counted (``send`` returns False; the node counts it in its
publisher's ``dropped``).

Errors: :class:`flexsheet.runtime.transport.TransportError` when an endpoint cannot be bound (address in use,
bad address).

Modules: :mod:`~flexsheet.runtime.zmq.frames` (multipart frames without blocking),
:mod:`~flexsheet.runtime.zmq.curve` (CURVE keys and the ZAP allow-list), :mod:`~flexsheet.runtime.zmq.xpub`
(publisher sockets), :mod:`~flexsheet.runtime.zmq.linkwatch` (links that heal),
:mod:`~flexsheet.runtime.zmq.subscriber` (the SUB side), :mod:`~flexsheet.runtime.zmq.transport` (a node's
transport), :mod:`~flexsheet.runtime.zmq.reqrep` (the services' request/reply sockets).
"""

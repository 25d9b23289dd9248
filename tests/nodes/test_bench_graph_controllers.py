"""The graph bench's controller twins (flexsheet.benches.graph.controllers): each in a process of its own,
its Modbus port open for the block and closed after it."""

import socket

from flexsheet.benches.graph import CONTROLLERS, controllers


def _open(port: int) -> bool:
    try:
        socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
        return True
    except OSError:
        return False


def test_both_controller_twins_listen_for_the_block_and_stop_after_it():
    with controllers():
        assert all(_open(p) for p in CONTROLLERS.values())
    assert not any(_open(p) for p in CONTROLLERS.values())

"""The bridge's protocol defaults (flexsheet.arm.bridge_config): a port or cycle left unset takes its
protocol's; one that is set stays."""

from __future__ import annotations

from types import SimpleNamespace

from flexsheet.arm.bridge_config import DEFAULT_PERIOD, DEFAULT_PORT, protocol_defaults


def test_unset_port_and_cycle_take_the_protocols_and_set_ones_stay():
    mxt = protocol_defaults(SimpleNamespace(protocol="mxt", port=None, period=None))
    assert (mxt.port, mxt.period) == (10000, 0.00711) == (DEFAULT_PORT["mxt"], DEFAULT_PERIOD["mxt"])
    modbus = protocol_defaults(SimpleNamespace(protocol="modbus", port=None, period=None))
    assert (modbus.port, modbus.period) == (15020, 0.0071)
    kept = protocol_defaults(SimpleNamespace(protocol="modbus", port=1502, period=0.004))
    assert (kept.port, kept.period) == (1502, 0.004)

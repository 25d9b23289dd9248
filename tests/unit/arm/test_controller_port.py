"""The arm controller port: its sources are entry points, named by an arm bridge's ``source``; each says which
clock and protocols reach it, and the arm PC's clock offset."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from flexsheet.arm.controller_port import SOURCES_GROUP, ControllerSource, controller_source
from flexsheet.model.truth_choice import TruthChoice
from flexsheet.twin.controller_source import TwinController
from flexsheet.twin.loopback import LoopbackModbusClient


def test_the_network_controller_carries_both_protocols_on_the_wall_clock_only():
    tcp = controller_source("tcp")
    assert issubclass(tcp, ControllerSource) and tcp.__module__ == "nodes.arm_bridge.links"
    assert tcp.protocols == {"modbus", "mxt"} and not tcp.paced_by_node and tcp.modbus_client() is None
    tcp.check_clock(SimpleNamespace(simulated=False))
    with pytest.raises(ValueError, match="source: sim"):
        tcp.check_clock(SimpleNamespace(simulated=True))
    assert tcp.clock_offset(SimpleNamespace(arm="left")) == 0.0          # chrony keeps the PCs together


def test_the_twin_is_modbus_in_process_on_a_simulated_clock_with_the_truths_clock_offset():
    assert controller_source("sim") is TwinController
    assert TwinController.protocols == {"modbus"} and TwinController.paced_by_node
    assert TwinController.modbus_client() is LoopbackModbusClient
    TwinController.check_clock(SimpleNamespace(simulated=True))
    with pytest.raises(ValueError, match="clock: sim"):
        TwinController.check_clock(SimpleNamespace(simulated=False))
    ideal = TwinController.clock_offset(SimpleNamespace(arm="left", twin=TruthChoice(realism="ideal")))
    real = [TwinController.clock_offset(SimpleNamespace(arm=a, twin=TruthChoice(truth_seed=3)))
            for a in ("left", "right")]
    assert ideal == 0.0 and all(0.0 < abs(o) <= 0.25e-3 for o in real) and real[0] != real[1]


def test_an_unknown_source_is_named_with_the_installed_ones():
    with pytest.raises(LookupError, match=rf"unknown controller source 'udp' \({SOURCES_GROUP}\); known: "
                                          r"sim, tcp"):
        controller_source("udp")


def test_the_network_controller_hands_out_a_link_by_address_and_the_twin_none():
    """``link`` builds the bridge's link to a controller at an address (the arm bench reaches its links so);
    a protocol the source does not carry is refused, and the in-process twin has no address to link to."""
    tcp = controller_source("tcp")
    modbus = tcp.link("modbus", "127.0.0.1", 15021, request_timeout=0.5)
    mxt = tcp.link("mxt", "127.0.0.1", 10000, period=0.00711, record=True)
    assert type(modbus).__name__ == "ModbusLink" and (modbus.host, modbus.port) == ("127.0.0.1", 15021)
    assert modbus.request_timeout == 0.5 and type(mxt).__name__ == "MxtLink"
    with pytest.raises(ValueError, match="carries protocol modbus or mxt, not profinet"):
        tcp.link("profinet", "127.0.0.1", 1)
    with pytest.raises(LookupError, match="TwinController opens no link"):
        TwinController.link("modbus", "127.0.0.1", 15021)

"""Domains: the domain from --domain or $FLEXSHEET_DOMAIN_ID, the ports a launch file gives moved by domain,
and the holder of a taken port named."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from flexsheet.runtime.domain import (
    DOMAIN_ENV,
    DOMAIN_STRIDE,
    MAX_DOMAIN,
    domain_id,
    port_holder,
    shift_params,
    shift_port,
)
from flexsheet.runtime.launch import load_launch
from flexsheet.runtime.launch_config import node_config

ROOT = Path(__file__).resolve().parents[3]


def test_the_domain_comes_from_the_argument_else_the_environment(monkeypatch):
    monkeypatch.delenv(DOMAIN_ENV, raising=False)
    assert domain_id() == 0
    monkeypatch.setenv(DOMAIN_ENV, "7")
    assert domain_id() == 7
    assert domain_id("3") == 3 and domain_id(0) == 0 and domain_id(MAX_DOMAIN) == MAX_DOMAIN


@pytest.mark.parametrize("bad", ["-1", "x", "3.5", str(MAX_DOMAIN + 1), " "])
def test_a_bad_domain_is_refused_naming_its_source_and_value(monkeypatch, bad):
    with pytest.raises(ValueError, match=rf"--domain must be an integer in 0\.\.{MAX_DOMAIN}, got '{bad}'"):
        domain_id(bad)
    if bad.strip():
        monkeypatch.setenv(DOMAIN_ENV, bad)
        with pytest.raises(ValueError, match=f"{DOMAIN_ENV} must be an integer"):
            domain_id()


def test_local_ports_move_by_the_stride_and_remote_ones_stay():
    assert shift_port(7400, 3) == 7400 + 3 * DOMAIN_STRIDE == 8150 and shift_port(0, 3) == 0
    assert shift_params({"port": 15021}, 2) == {"port": 15521}
    assert shift_params({"host": "127.0.0.1", "port": 15021, "rate": 5}, 2) == {"host": "127.0.0.1",
                                                                                "port": 15521,
                                                                                  "rate": 5}
    assert shift_params({"host": "192.168.10.2", "port": 10000}, 2) == {"host": "192.168.10.2", "port": 10000}
    assert shift_params({"ws_port": 8765, "port": 0}, 1) == {"ws_port": 9015, "port": 0}
    assert shift_params({"port": 15021}, 0) == {"port": 15021}


def test_a_launch_file_in_domain_4_binds_its_own_ports(monkeypatch):
    monkeypatch.delenv(DOMAIN_ENV, raising=False)
    lf0 = load_launch(ROOT / "launch" / "sim.yaml")
    monkeypatch.setenv(DOMAIN_ENV, "4")
    lf4 = load_launch(ROOT / "launch" / "sim.yaml")
    off = 4 * DOMAIN_STRIDE
    for name, ep in lf0.endpoints().items():
        assert lf4.endpoint_of(name) == ep.rsplit(":", 1)[0] + f":{int(ep.rsplit(':', 1)[1]) + off}"
    assert node_config(lf4, "ctrl_left").params["port"] == 15021 + off
    assert node_config(lf4, "arm_left").params["port"] == 15021 + off          # the bridge follows its twin
    assert node_config(lf4, "viz").params["port"] == 8765 + off
    lab = load_launch(ROOT / "launch" / "lab.yaml")
    bridge = shift_params(lab.nodes["arm_left"].params, 4)
    assert (bridge["host"], bridge["port"]) == ("192.168.10.2", 10000)          # a real controller stays


def test_the_holder_of_a_listening_port_is_named():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen()
    try:
        who = port_holder(s.getsockname()[1])
        assert who.startswith("pid ") and "python" in who, who
    finally:
        s.close()
    assert port_holder(1) == ""

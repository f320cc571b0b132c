"""--ray-address and RAY_ADDRESS: a malformed address is one line before Ray starts; an
address that accepts connections but is no Ray cluster fails within seconds, one line,
without Ray's log lines (before: a ValueError traceback; 26 s and 20 lines of Ray log)."""

from __future__ import annotations

import socket
import threading
import time

import pytest

from tether_gym_agents.cli.train import main
from tether_gym_agents.training import fanout
from tether_gym_agents.training.config import ConfigError
from tether_gym_agents.training.settings import check_ray_address


@pytest.mark.parametrize("address", ["garbage", "", " ", "host:", ":6379", "host:0",
                                     "host:65536", "host:12x", "a b:1", "[zz]:1",
                                     "ray://", "http://host:1", "1:2:3"])
def test_malformed_address_is_one_line_before_ray(tmp_path, capsys, monkeypatch, address):
    monkeypatch.setattr(fanout, "require_ray", lambda: pytest.fail("Ray was started"))
    assert main(["--seeds", "2", "--ray-address", address, "--timesteps", "64",
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"train.py: error: --ray-address {address!r} is not a Ray address")
    assert "HOST:PORT" in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("address", ["auto", "local", "10.0.0.1:6379", "ray://head:10001",
                                     "[::1]:6379", "ray_head.cluster.local:6379"])
def test_valid_forms_pass(address):
    assert check_ray_address(address) == address


def test_malformed_ray_address_variable_is_named(monkeypatch):
    monkeypatch.setenv("RAY_ADDRESS", "not an address")
    monkeypatch.setattr(fanout, "require_ray", lambda: pytest.fail("Ray was started"))
    with pytest.raises(ConfigError, match="RAY_ADDRESS 'not an address' is not a Ray address"):
        fanout.init_ray(None)


@pytest.fixture
def silent_server():
    """A TCP port that accepts connections and never answers (a proxy, not Ray)."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(16)
    held = []

    def serve():
        while True:
            try:
                conn, _ = srv.accept()
            except OSError:
                return
            held.append(conn)

    threading.Thread(target=serve, daemon=True).start()
    yield srv.getsockname()[1]
    srv.close()
    for conn in held:
        conn.close()


def test_address_that_is_no_ray_cluster_fails_fast_in_one_line(tmp_path, capfd, monkeypatch,
                                                               silent_server):
    pytest.importorskip("ray")
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    monkeypatch.setattr(fanout, "GCS_PROBE_S", 4.0)
    monkeypatch.setattr(fanout, "train", lambda s: pytest.fail("trained"))
    start = time.monotonic()
    assert main(["--seeds", "2", "--ray-address", f"127.0.0.1:{silent_server}",
                 "--timesteps", "64", "--out", str(tmp_path / "o")]) == 2
    assert time.monotonic() - start < 30  # before: about 40 s per try, 20 tries
    err = capfd.readouterr().err  # file-descriptor level: Ray's C++ lines would show here
    assert err.startswith("train.py: error: cannot connect to the Ray cluster at "
                          f"--ray-address/RAY_ADDRESS '127.0.0.1:{silent_server}'")
    assert "no Ray cluster answered within 4 s" in err
    assert len(err.strip().splitlines()) == 1, err

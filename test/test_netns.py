"""The simulated network of issue 21's host tests (``test/netns.py``): hosts as network namespaces,
real DDS over real UDP between them, an impaired link, and nothing left behind.

- a plain rclpy publisher in one host and a subscriber in another discover each other and exchange
  every message, and the traffic went through the hosts' ``eth0`` (the link), not loopback;
- the impaired link delays (a UDP echo takes at least twice the one-way delay) and drops (the hub
  counts drops) yet a reliable topic delivers every message;
- a rate-limited link (``tc tbf``) takes at least the time its rate says for a TCP transfer;
- a host killed loses its processes, the other host keeps running; a host disconnected (its cable
  pulled) is unreachable until it is reconnected;
- closing the network, also when the body raises (an error, Ctrl-C) or when the process that opened
  it is killed, leaves no process and no namespace.

DDS domains 170-176. Skipped only where unprivileged user namespaces are missing.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from netns import Impairment, Network, processes_in, unavailable

HERE = Path(__file__).resolve().parent
PEER = HERE / "data" / "dds_peer.py"

REASON = unavailable()
pytestmark = pytest.mark.skipif(REASON is not None, reason=f"no simulated network here: {REASON}")

ECHO = """
import socket, sys
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.bind(("0.0.0.0", 5000))
print("bound", flush=True)
while True:
    data, peer = s.recvfrom(100)
    s.sendto(data, peer)
"""
PING = """
import socket, sys, time
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.settimeout(5)
trips = []
for i in range(3):
    start = time.monotonic()
    s.sendto(b"x", (sys.argv[1], 5000))
    s.recvfrom(100)
    trips.append(time.monotonic() - start)
print(min(trips))
"""

DAEMON = "import os, time\nif os.fork() == 0:\n    os.setsid()\n    time.sleep(60)\n"
"""A process that leaves its parent (double fork, own session): found through its namespace only."""


def alive(pid: int) -> bool:
    """``pid`` exists and is not a zombie."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def exchange(net: Network, count: int, topic: str) -> list[int]:
    """A plain rclpy subscriber in ``graphics`` and publisher in ``robot``; what the subscriber got."""
    sub = net["graphics"].popen([sys.executable, str(PEER), "sub", topic, str(count)], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
    pub = net["robot"].run([sys.executable, str(PEER), "pub", topic, str(count)], capture_output=True, text=True,
                           timeout=40)
    out, err = sub.communicate(timeout=40)
    assert pub.returncode == 0, pub.stderr
    assert sub.returncode == 0, f"{out}\n{err}"
    received: list[int] = json.loads(out)
    return received


def test_rclpy_peers_in_two_hosts_talk_over_the_link() -> None:
    with Network(["robot", "graphics"], domain=170) as net:
        assert net.link == "bridge"
        assert net["robot"].address != net["graphics"].address
        before = {name: host.interface_counters() for name, host in net.hosts.items()}
        received = exchange(net, 50, "netns_chat")
        assert received == list(range(50))
        after = {name: host.interface_counters() for name, host in net.hosts.items()}
    # Real UDP through each host's eth0: at least one packet per message out of robot and into graphics.
    assert after["robot"]["tx_packets"] - before["robot"]["tx_packets"] >= 50
    assert after["graphics"]["rx_packets"] - before["graphics"]["rx_packets"] >= 50


def test_an_impaired_link_delays_and_drops_yet_a_reliable_topic_delivers_every_message() -> None:
    delay = 0.015
    with Network(["robot", "graphics"], domain=171, impairment=Impairment(delay_s=delay, loss=0.1, seed=21)) as net:
        assert net.link == "hub"
        echo = net["graphics"].popen([sys.executable, "-c", ECHO], stdout=subprocess.PIPE, text=True)
        assert echo.stdout is not None and echo.stdout.readline() == "bound\n"
        # Losses may eat a probe (its socket then times out): the echo is tried on a clean link.
        net.impair(Impairment(delay_s=delay, loss=0.0))
        ping = net["robot"].run([sys.executable, "-c", PING, net["graphics"].address], capture_output=True,
                                text=True, timeout=30)
        assert ping.returncode == 0, ping.stderr
        assert float(ping.stdout) >= 2 * delay
        net.impair(Impairment(delay_s=delay, loss=0.1, seed=21))
        received = exchange(net, 100, "netns_lossy")
        counters = net.counters()
    assert received == list(range(100))
    assert counters["robot->graphics"]["forwarded"] >= 100
    assert counters["robot->graphics"]["dropped"] + counters["graphics->robot"]["dropped"] > 0


SERVE = """
import socket, time
server = socket.create_server(("0.0.0.0", 5001))
print("listening", flush=True)
connection, _ = server.accept()
first = None
total = 0
while data := connection.recv(1 << 16):
    first = first or time.monotonic()
    total += len(data)
print(total, time.monotonic() - first, flush=True)
"""
SEND = """
import socket, sys
with socket.create_connection((sys.argv[1], 5001)) as connection:
    connection.sendall(bytes(int(sys.argv[2])))
"""


def test_a_rate_limited_link_takes_the_time_its_rate_says() -> None:
    size, mbit = 1_000_000, 20.0
    with Network(["robot", "graphics"], domain=176) as net:
        net.limit(None)  # no limit to lift: nothing happens
        net.limit(mbit)
        server = net["graphics"].popen([sys.executable, "-c", SERVE], stdout=subprocess.PIPE, text=True)
        assert server.stdout is not None and server.stdout.readline() == "listening\n"
        sent = net["robot"].run([sys.executable, "-c", SEND, net["graphics"].address, str(size)], timeout=30)
        assert sent.returncode == 0
        received, seconds = server.stdout.readline().split()
        net.limit(None)
    assert int(received) == size
    # The token bucket lets its burst (1 ms of traffic, at least 32 kB) through at once, then the rate.
    assert float(seconds) >= (size - 32_000) * 8 / (mbit * 1e6) * 0.9


def test_a_killed_host_loses_its_processes_and_the_other_keeps_running() -> None:
    with Network(["robot", "graphics"], domain=172) as net:
        robot = net["robot"].popen(["sleep", "60"])
        graphics = net["graphics"].popen(["sleep", "60"])
        net["robot"].run([sys.executable, "-c", DAEMON], timeout=10)
        net["robot"].kill()
        assert robot.wait(timeout=10) == -signal.SIGKILL
        assert processes_in({net["robot"].netns}) == [net["robot"].pid]  # the daemon too; the holder stays
        assert graphics.poll() is None
        again = net["robot"].run(["true"], timeout=10)  # the host is still there for a new start
        assert again.returncode == 0


def test_a_disconnected_host_is_unreachable_until_it_is_reconnected() -> None:
    with Network(["robot", "graphics"], domain=175) as net:
        echo = net["graphics"].popen([sys.executable, "-c", ECHO], stdout=subprocess.PIPE, text=True)
        assert echo.stdout is not None and echo.stdout.readline() == "bound\n"
        ping = [sys.executable, "-c", PING.replace("settimeout(5)", "settimeout(0.5)"), net["graphics"].address]
        assert net["robot"].run(ping, capture_output=True, timeout=30).returncode == 0
        net["graphics"].disconnect()
        assert net["robot"].run(ping, capture_output=True, timeout=30).returncode != 0  # socket.timeout
        assert echo.poll() is None  # its processes run on
        net["graphics"].reconnect()
        assert net["robot"].run(ping, capture_output=True, timeout=30).returncode == 0
        routes = net["graphics"].run(["ip", "route"], capture_output=True, text=True, timeout=10).stdout
        assert "224.0.0.0/4 dev eth0" in routes


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_closing_leaves_no_process_and_no_namespace_also_when_the_body_raises(error: type[BaseException]) -> None:
    with pytest.raises(error):
        with Network(["robot", "graphics", "tracker"], domain=173) as net:
            namespaces = set(net.namespaces)
            keeper = net.keeper_pid
            started = [net[name].popen(["sleep", "60"]) for name in net.hosts]
            net["graphics"].run([sys.executable, "-c", DAEMON], timeout=10)
            assert len(processes_in(namespaces)) >= 3 + 1 + 3  # sleepers, the daemon, the hosts' holders
            raise error("the body failed")
    assert len(namespaces) == 3
    assert not alive(keeper)
    assert all(process.returncode is not None for process in started)
    assert processes_in(namespaces) == []


def test_the_network_goes_when_the_process_that_opened_it_is_killed() -> None:
    opener = subprocess.Popen(
        [sys.executable, "-c", "import json, sys\nfrom netns import Network\n"
         "net = Network(['robot', 'graphics'], domain=174).__enter__()\n"
         "sleeper = net['robot'].popen(['sleep', '60'])\n"
         "print(json.dumps([sorted(net.namespaces), net.keeper_pid, sleeper.pid]), flush=True)\n"
         "sys.stdin.read()\n"],
        cwd=HERE, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert opener.stdout is not None
        namespaces, keeper, sleeper = json.loads(opener.stdout.readline())
        assert alive(keeper) and alive(sleeper)
    finally:
        opener.kill()
        opener.wait()
    deadline = time.monotonic() + 15
    while (alive(keeper) or processes_in(set(namespaces))) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not alive(keeper)
    assert processes_in(set(namespaces)) == []
    assert not alive(sleeper)

"""The keeper of a simulated network (``netns.py``): the one process that owns its namespaces.

``netns.Network`` starts it as ``unshare -r -n --fork --kill-child=SIGTERM python netns_keeper.py
CONFIG``: root of a user namespace of its own (so no privilege is needed on the machine) in a
network namespace of its own, the *wire*. In it the keeper makes one network namespace per host (a
sleeping ``unshare -n`` child that dies with the keeper), joins them with the link (a kernel bridge
with one veth pair per host, or the impairment hub of ``netns_relay.py`` with one TAP device per
host), gives each host its address, loopback and a multicast route, prints one JSON line with the
hosts, and then serves commands, one JSON object a line on stdin, one answer a line on stdout:

- ``{"op": "counters"}``: the hub's frames forwarded and dropped per direction (``{}`` on a bridge);
- ``{"op": "impair", "delay_s": .., "loss": .., "seed": ..}``: change the hub's impairment;
- ``{"op": "rate", "mbit": .. or null}``: limit what every host sends (``tc tbf`` on its ``eth0``,
  which the kernel has where it lacks netem), or lift the limit;
- ``{"op": "kill", "host": NAME}``: SIGKILL every process in that host's namespace (a host that
  dies; the namespace itself stays, as a powered-off machine's cable does).

End of stdin (the network closed, or the process that opened it gone, however it died) or SIGTERM:
every process in every host's namespace is killed, the hosts' namespaces go with their sleepers and
the wire with the keeper.
"""

from __future__ import annotations

import ctypes
import json
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from netns import netns_of
from netns_relay import Hub, Impairment, open_tap

PR_SET_PDEATHSIG = 1
INTERFACE = "eth0"


def die_with_parent() -> None:
    """In a child before exec: SIGKILL when the keeper dies (the keeper has one thread: safe)."""
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)


def sweep(namespaces: set[int], spare: set[int]) -> int:
    """SIGKILL every process in ``namespaces`` but ``spare`` until none is left (a dying process may
    fork once more); the number killed."""
    killed = 0
    for _ in range(100):
        found = []
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit() and int(entry.name) not in spare and netns_of(int(entry.name)) in namespaces:
                found.append(int(entry.name))
        if not found:
            return killed
        for pid in found:
            try:
                os.kill(pid, signal.SIGKILL)
                killed += 1
            except ProcessLookupError:
                pass
        time.sleep(0.01)
    raise RuntimeError(f"processes keep appearing in the hosts' namespaces: {found}")


def ip(commands: list[str], pid: int | None = None) -> None:
    """``ip -batch`` in the wire (``pid`` None) or in the namespace of ``pid``."""
    argv = ["ip", "-batch", "-"]
    if pid is not None:
        argv = ["nsenter", "-t", str(pid), "-n", *argv]
    result = subprocess.run(argv, input="\n".join(commands) + "\n", capture_output=True, text=True)
    if result.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} failed: {result.stderr.strip()}\n" + "\n".join(commands))


class Keeper:
    def __init__(self, config: dict[str, Any]) -> None:
        self.names: list[str] = config["hosts"]
        self.prefix: str = config["subnet"]
        self.mtu: int = config["mtu"]
        self.sleepers: dict[str, subprocess.Popen[bytes]] = {}
        self.namespaces: dict[str, int] = {}
        self.hub: Hub | None = None
        self.rate: float | None = None
        """The plain link's limit toward each host (megabits a second), None: none."""
        impairment = config.get("impairment")
        self.impairment = Impairment(**impairment) if impairment is not None else None

    def start(self) -> dict[str, Any]:
        ip(["link set lo up"])
        wire = netns_of(os.getpid())
        for name in self.names:
            sleeper = subprocess.Popen(["unshare", "-n", "sleep", "infinity"], preexec_fn=die_with_parent,
                                       stdin=subprocess.DEVNULL)
            self.sleepers[name] = sleeper
            deadline = time.monotonic() + 10
            while (netns := netns_of(sleeper.pid)) in (None, wire):
                if sleeper.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"host {name}: `unshare -n` made no network namespace "
                                       f"(exit status {sleeper.returncode})")
                time.sleep(0.002)
            self.namespaces[name] = netns
        if self.impairment is None:
            self._bridge()
        else:
            self._hub(self.impairment)
        hosts = {}
        for index, name in enumerate(self.names):
            address = f"{self.prefix}.{index + 1}"
            ip(["link set lo up", f"link set {INTERFACE} up", f"addr add {address}/24 dev {INTERFACE}",
                f"route add 224.0.0.0/4 dev {INTERFACE}"], self.sleepers[name].pid)
            hosts[name] = {"pid": self.sleepers[name].pid, "address": address, "netns": self.namespaces[name],
                           "interface": INTERFACE}
        return {"ready": True, "keeper": os.getpid(), "hosts": hosts, "link": "bridge" if self.hub is None else "hub"}

    def _bridge(self) -> None:
        """A kernel bridge in the wire (multicast snooping off: no IGMP querier here would keep its
        table, and DDS discovery must reach every host) and one veth pair per host."""
        commands = ["link add br0 type bridge mcast_snooping 0", "link set br0 up"]
        for index, name in enumerate(self.names):
            commands += [f"link add h{index} mtu {self.mtu} type veth peer name {INTERFACE} mtu {self.mtu} "
                         f"netns {self.sleepers[name].pid}", f"link set h{index} master br0 up"]
        ip(commands)

    def limit(self, mbit: float | None) -> None:
        """Every host's ``eth0`` sends at most ``mbit`` megabits a second (a token bucket on its egress,
        as a NIC's line rate: a sender that outruns it waits for its socket's buffer, as on a real
        link, instead of losing what a switch's queue would drop), or without limit (None)."""
        if mbit is None and self.rate is None:
            return
        for name in self.names:
            if mbit is None:
                tc = ["tc", "qdisc", "del", "dev", INTERFACE, "root"]
            else:
                bucket = max(32_000, int(mbit * 1e6 / 8 / 1000))  # 1 ms of traffic, at least a few frames
                tc = ["tc", "qdisc", "replace", "dev", INTERFACE, "root", "tbf", "rate", f"{mbit}mbit",
                      "burst", str(bucket), "latency", "50ms"]
            argv = ["nsenter", "-t", str(self.sleepers[name].pid), "-n", *tc]
            result = subprocess.run(argv, capture_output=True, text=True)
            if result.returncode != 0:
                raise ValueError(f"{' '.join(tc)} in host {name} failed: {result.stderr.strip()}")
        self.rate = mbit

    def _hub(self, impairment: Impairment) -> None:
        """One TAP device per host, made here and moved into the host (its descriptor stays the hub's)."""
        ports = {}
        for index, name in enumerate(self.names):
            ports[name] = open_tap(f"tap{index}")
            ip([f"link set tap{index} mtu {self.mtu} netns {self.sleepers[name].pid}"])
            ip([f"link set tap{index} name {INTERFACE}"], self.sleepers[name].pid)
        self.hub = Hub(ports, impairment)

    def serve(self) -> None:
        """Answer commands and run the hub until stdin ends."""
        pending = b""
        stdin = sys.stdin.fileno()
        while True:
            now = Hub.now()
            timeout = self.hub.timeout(now) if self.hub is not None else None
            ready, _, _ = select.select([stdin, *(self.hub.fds() if self.hub else [])], [], [], timeout)
            now = Hub.now()
            for fd in ready:
                if fd == stdin:
                    chunk = os.read(stdin, 65536)
                    if not chunk:
                        return
                    pending += chunk
                    while b"\n" in pending:
                        line, pending = pending.split(b"\n", 1)
                        self.answer(json.loads(line))
                elif self.hub is not None:
                    self.hub.readable(fd, now)
            if self.hub is not None:
                self.hub.flush(Hub.now())

    def answer(self, command: dict[str, Any]) -> None:
        op = command.get("op")
        try:
            if op == "counters":
                reply: dict[str, Any] = {"counters": self.hub.counters() if self.hub else {}}
            elif op == "impair":
                if self.hub is None:
                    raise ValueError("this network's link is a plain bridge: open it with an impairment to "
                                     "change one")
                self.hub.set_impairment(Impairment(command["delay_s"], command["loss"], command.get("seed", 0)))
                reply = {"ok": True}
            elif op == "rate":
                if self.hub is not None:
                    raise ValueError("a rate limit is for the plain link (a bridge); the impaired one is the hub's")
                self.limit(command["mbit"])
                reply = {"ok": True}
            elif op == "kill":
                host = command["host"]
                if host not in self.namespaces:
                    raise ValueError(f"no host {host!r}; hosts: {', '.join(self.names)}")
                spare = {sleeper.pid for sleeper in self.sleepers.values()} | {os.getpid()}
                reply = {"killed": sweep({self.namespaces[host]}, spare)}
            else:
                raise ValueError(f"unknown op {op!r}; ops: counters, impair, rate, kill")
        except (ValueError, KeyError, TypeError) as error:
            reply = {"error": str(error)}
        sys.stdout.write(json.dumps(reply) + "\n")
        sys.stdout.flush()

    def close(self) -> None:
        """Every process in the hosts' namespaces killed, then the sleepers: the namespaces go with them."""
        spare = {sleeper.pid for sleeper in self.sleepers.values()} | {os.getpid()}
        try:
            sweep(set(self.namespaces.values()), spare)
        finally:
            for sleeper in self.sleepers.values():
                sleeper.kill()
                sleeper.wait()
            if self.hub is not None:
                for fd in self.hub.fds():
                    os.close(fd)


def main() -> None:
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the opener's to handle: it closes stdin
    keeper = Keeper(json.loads(sys.argv[1]))
    try:
        try:
            ready = keeper.start()
        except Exception as error:  # told to the opener, which raises it with this text
            sys.stdout.write(json.dumps({"error": f"{type(error).__name__}: {error}"}) + "\n")
            sys.stdout.flush()
            return
        sys.stdout.write(json.dumps(ready) + "\n")
        sys.stdout.flush()
        keeper.serve()
    finally:
        keeper.close()


if __name__ == "__main__":
    main()

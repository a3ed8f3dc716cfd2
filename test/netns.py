"""Simulated hosts on this machine: Linux network namespaces joined by a link, for tests and benchmarks
of an application spread over several hosts (issue 21), with real DDS over real UDP between them.

    from netns import Network, Impairment

    with Network(["robot", "graphics"], domain=170) as net:          # a plain link (kernel bridge)
        sub = net["graphics"].popen([sys.executable, "sub.py"], stdout=subprocess.PIPE)
        net["robot"].run([sys.executable, "pub.py"], timeout=30)
        net["robot"].kill()                                          # the robot host dies
        net["graphics"].disconnect(); net["graphics"].reconnect()    # a cable pulled, and back
        net["graphics"].interface_counters()                         # packets through its eth0

    with Network(["robot", "graphics"], domain=171, impairment=Impairment(delay_s=0.02, loss=0.05)) as net:
        ...
        net.counters()      # {"robot->graphics": {"forwarded": .., "dropped": .., ...}, ...}
        net.impair(Impairment(delay_s=0, loss=0.2, seed=3))        # change it mid-run

    with Network(["robot", "graphics"], domain=172) as net:
        net.limit(1000)     # a gigabit link (tc tbf on each host's eth0); net.limit(None) lifts it

Each host is a network namespace with loopback, an ``eth0`` at ``10.77.0.N/24`` (N from 1, in the
order given; ``subnet`` changes the prefix) and a route for multicast (DDS discovery). Commands run
in a host through ``nsenter`` into the namespace, with the DDS environment that makes two hosts
really talk over the link: ``FASTDDS_BUILTIN_TRANSPORTS=UDPv4`` (else Fast DDS takes its
shared-memory shortcut between processes of one machine), ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET``
and the network's ``ROS_DOMAIN_ID``.

The link is a kernel bridge with one veth pair per host, or, with an :class:`Impairment`, a hub in
user space that delays and drops frames (``netns_relay.py``): it stands in for ``tc netem``, which
the kernel here lacks (``CONFIG_NET_SCH_NETEM is not set``).

No privilege is needed: one *keeper* process (``netns_keeper.py``), root of a user namespace of
its own, owns every namespace. Closing the network (also on an exception or Ctrl-C in the body, and
when the process that opened it dies, since the keeper then reads the end of its stdin) kills every
process in every host, and the namespaces go with the keeper. :func:`unavailable` says why a
machine cannot do it (no unprivileged user namespaces), for a test to skip with that reason.

Also a command for trying things by hand::

    python test/netns.py robot graphics [--domain 170] [--delay-ms 20 --loss 0.05]

prints each host's address and the command that opens a shell in it, and holds the network until
Ctrl-C.
"""

from __future__ import annotations

import argparse
import json
import os
import select
import shlex
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict
from pathlib import Path
from typing import IO, Any, Mapping, Sequence

from netns_relay import Impairment

__all__ = ["Host", "Impairment", "Network", "NetworkError", "unavailable", "processes_in"]

HERE = Path(__file__).resolve().parent
KEEPER = HERE / "netns_keeper.py"
START_TIMEOUT_S = 20.0


class NetworkError(RuntimeError):
    """The simulated network could not be made, or its keeper failed."""


def unavailable() -> str | None:
    """Why this machine cannot make a simulated network (None: it can)."""
    for tool in ("unshare", "nsenter", "ip"):
        if not any((Path(folder) / tool).exists() for folder in os.environ.get("PATH", "").split(os.pathsep)
                   + ["/usr/sbin", "/sbin"]):
            return f"`{tool}` is not installed (util-linux / iproute2)"
    probe = subprocess.run(["unshare", "-r", "-n", "true"], capture_output=True, text=True)
    if probe.returncode != 0:
        return f"unprivileged user and network namespaces are not available: {probe.stderr.strip()}"
    return None


def netns_of(pid: int) -> int | None:
    """The inode of ``pid``'s network namespace; None when it is gone (or a zombie)."""
    try:
        return os.stat(f"/proc/{pid}/ns/net").st_ino
    except OSError:
        return None


def processes_in(namespaces: set[int]) -> list[int]:
    """The processes whose network namespace (inode) is one of ``namespaces``: none once a network
    is closed, which is how a test checks that nothing is left."""
    return [int(entry.name) for entry in Path("/proc").iterdir()
            if entry.name.isdigit() and netns_of(int(entry.name)) in namespaces]


class Host:
    """One simulated host: a network namespace on the network's link."""

    def __init__(self, network: Network, name: str, info: Mapping[str, Any]) -> None:
        self.network = network
        self.name = name
        self.address: str = info["address"]
        """Its IPv4 address on the link."""
        self.interface: str = info["interface"]
        self.pid: int = info["pid"]
        """The process that holds its namespace (not one to signal: the keeper owns it)."""
        self.netns: int = info["netns"]
        """Its network namespace's inode."""

    def __repr__(self) -> str:
        return f"Host({self.name!r}, {self.address})"

    def command(self, argv: Sequence[str]) -> list[str]:
        """``argv`` as run in this host."""
        return ["nsenter", "--preserve-credentials", "-U", "-n", "-t", str(self.pid), "--", *argv]

    def environment(self, env: Mapping[str, str] | None = None) -> dict[str, str]:
        """``env`` (default: this process's environment) with the host's DDS settings over it."""
        merged = dict(os.environ if env is None else env)
        merged.update(FASTDDS_BUILTIN_TRANSPORTS="UDPv4", ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET",
                      ROS_DOMAIN_ID=str(self.network.domain))
        merged.pop("ROS_LOCALHOST_ONLY", None)
        merged.pop("ROS_STATIC_PEERS", None)
        return merged

    def popen(self, argv: Sequence[str], env: Mapping[str, str] | None = None, **kwargs: Any) -> subprocess.Popen[Any]:
        """Start ``argv`` in this host (``subprocess.Popen`` arguments pass through; the process is
        the command itself, so its signals and exit status are the command's)."""
        process: subprocess.Popen[Any] = subprocess.Popen(self.command(argv), env=self.environment(env), **kwargs)
        self.network.started.append((self, process))
        # Returned once it is in the host (nsenter has entered the namespace), so that a kill or a close
        # that follows at once finds it there.
        deadline = time.monotonic() + START_TIMEOUT_S
        while netns_of(process.pid) != self.netns and process.poll() is None:
            if time.monotonic() > deadline:
                raise NetworkError(f"host {self.name}: {argv[0]} did not enter the host's namespace in "
                                   f"{START_TIMEOUT_S:.0f} s")
            time.sleep(0.001)
        return process

    def run(self, argv: Sequence[str], env: Mapping[str, str] | None = None, timeout: float | None = None,
            **kwargs: Any) -> subprocess.CompletedProcess[Any]:
        """Run ``argv`` in this host to its end (``subprocess.run`` arguments pass through)."""
        return subprocess.run(self.command(argv), env=self.environment(env), timeout=timeout, **kwargs)

    def kill(self) -> None:
        """SIGKILL every process in this host, as if the machine lost power; the host stays on the
        link: new commands may run in it. What :meth:`popen` started here is killed by its id (it may
        not have entered the namespace yet), everything else found in the namespace by the keeper."""
        for host, process in self.network.started:
            if host is self and process.poll() is None:
                process.kill()
        self.network.ask({"op": "kill", "host": self.name})

    def disconnect(self) -> None:
        """Take this host off the link (its ``eth0`` down: a cable pulled), its processes running on."""
        self._ip(["link set dev {eth} down"])

    def reconnect(self) -> None:
        """Put it back on the link (the multicast route, gone with the interface, made again)."""
        self._ip(["link set dev {eth} up", "route replace 224.0.0.0/4 dev {eth}"])

    def _ip(self, commands: list[str]) -> None:
        script = "\n".join(command.format(eth=self.interface) for command in commands) + "\n"
        result = self.run(["ip", "-batch", "-"], input=script, capture_output=True, text=True, timeout=10)
        if result.returncode != 0:
            raise NetworkError(f"host {self.name}: ip failed: {result.stderr.strip()}")

    def interface_counters(self) -> dict[str, int]:
        """Bytes and packets received and sent by this host's ``eth0`` (from its ``/proc/net/dev``):
        traffic that went over the link, not over loopback."""
        for line in Path(f"/proc/{self.pid}/net/dev").read_text().splitlines()[2:]:
            name, values = line.split(":", 1)
            if name.strip() == self.interface:
                fields = [int(v) for v in values.split()]
                return {"rx_bytes": fields[0], "rx_packets": fields[1], "tx_bytes": fields[8],
                        "tx_packets": fields[9]}
        raise NetworkError(f"host {self.name} has no interface {self.interface}")


class Network:
    """Named hosts joined by one link; a context manager (``with Network([...], domain=N) as net``)."""

    def __init__(self, hosts: Sequence[str], domain: int, impairment: Impairment | None = None,
                 subnet: str = "10.77.0", mtu: int = 1500) -> None:
        if len(set(hosts)) != len(hosts) or not hosts:
            raise ValueError(f"hosts must be distinct names, got {list(hosts)}")
        if len(hosts) > 250:
            raise ValueError("at most 250 hosts on one /24 link")
        self.names = list(hosts)
        self.domain = domain
        self.impairment = impairment
        self.subnet = subnet
        self.mtu = mtu
        self.hosts: dict[str, Host] = {}
        self.started: list[tuple[Host, subprocess.Popen[Any]]] = []
        """Every process started with :meth:`Host.popen`, reaped at the close."""
        self.namespaces: set[int] = set()
        self.link = ""
        """``bridge`` (plain) or ``hub`` (impaired)."""
        self.keeper_pid = 0
        """The keeper's process id (0 before the open): gone after the close."""
        self._keeper: subprocess.Popen[bytes] | None = None
        self._log: IO[bytes] | None = None

    def __getitem__(self, name: str) -> Host:
        try:
            return self.hosts[name]
        except KeyError:
            raise KeyError(f"no host {name!r}; hosts: {', '.join(self.hosts)}") from None

    def __enter__(self) -> Network:
        try:
            self._open()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _open(self) -> None:
        config = {"hosts": self.names, "subnet": self.subnet, "mtu": self.mtu,
                  "impairment": None if self.impairment is None else asdict(self.impairment)}
        self._log = tempfile.TemporaryFile()
        self._keeper = subprocess.Popen(
            ["unshare", "-r", "-n", "--fork", "--kill-child=SIGTERM", sys.executable, str(KEEPER),
             json.dumps(config)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._log, cwd=HERE,
            start_new_session=True)  # Ctrl-C in a terminal is this process's to handle, not the keeper's
        ready = self._read(START_TIMEOUT_S)
        if "error" in ready:
            raise NetworkError(f"the simulated network could not be made: {ready['error']}")
        self.link = ready["link"]
        self.keeper_pid = ready["keeper"]
        for name in self.names:
            self.hosts[name] = Host(self, name, ready["hosts"][name])
            self.namespaces.add(self.hosts[name].netns)

    def _read(self, timeout_s: float) -> dict[str, Any]:
        assert self._keeper is not None and self._keeper.stdout is not None
        ready, _, _ = select.select([self._keeper.stdout], [], [], timeout_s)
        line = self._keeper.stdout.readline() if ready else b""
        if not line:
            raise NetworkError(f"the network's keeper {'gave no answer' if ready else 'did not answer in time'}"
                               f": {self._keeper_log()}")
        answer: dict[str, Any] = json.loads(line)
        return answer

    def _keeper_log(self) -> str:
        if self._log is None:
            return ""
        self._log.seek(0)
        return self._log.read().decode(errors="replace").strip() or "(no output)"

    def ask(self, command: dict[str, Any]) -> dict[str, Any]:
        """Send the keeper one command and return its answer (``netns_keeper.py`` lists them)."""
        if self._keeper is None or self._keeper.stdin is None or self._keeper.poll() is not None:
            raise NetworkError("the network is not open")
        self._keeper.stdin.write(json.dumps(command).encode() + b"\n")
        self._keeper.stdin.flush()
        answer = self._read(10.0)
        if "error" in answer:
            raise NetworkError(answer["error"])
        return answer

    def counters(self) -> dict[str, dict[str, int]]:
        """The impaired link's frames per direction (``robot->graphics``): forwarded, dropped (by the
        impairment), failed (the destination's interface refused them), bytes; ``{}`` on a plain link."""
        counters: dict[str, dict[str, int]] = self.ask({"op": "counters"})["counters"]
        return counters

    def limit(self, mbit: float | None) -> None:
        """Limit what each host sends to ``mbit`` megabits a second, as its network card's line rate
        (``tc tbf`` on its ``eth0``), or lift the limit (None): a veth alone moves data at memory
        speed, no real link does."""
        self.ask({"op": "rate", "mbit": mbit})

    def impair(self, impairment: Impairment) -> None:
        """Change the impaired link's delay and loss from now on (a network opened with an impairment)."""
        self.ask({"op": "impair", **asdict(impairment)})
        self.impairment = impairment

    def close(self) -> None:
        """Kill every process in every host, remove the namespaces, reap what :meth:`Host.popen` started.
        Safe to call twice."""
        keeper, self._keeper = self._keeper, None
        if keeper is not None:
            try:
                if keeper.stdin is not None:
                    keeper.stdin.close()  # the keeper's end of stdin: it sweeps the hosts and exits
                keeper.wait(timeout=15)
            except subprocess.TimeoutExpired:
                keeper.kill()  # unshare --kill-child passes SIGTERM on to the keeper, which sweeps
                keeper.wait()
            finally:
                if keeper.stdout is not None:
                    keeper.stdout.close()
        for _, process in self.started:
            if process.poll() is None:
                process.kill()  # not in a host (it left its namespace): still ours to stop
            process.wait()
            for stream in (process.stdin, process.stdout, process.stderr):
                if stream is not None:
                    stream.close()
        if self._log is not None:
            self._log.close()
            self._log = None

    def leftovers(self) -> list[int]:
        """Processes still in one of this network's namespaces (none after :meth:`close`)."""
        return processes_in(self.namespaces)


def main() -> None:
    parser = argparse.ArgumentParser(prog="test/netns.py", description=__doc__.splitlines()[0])
    parser.add_argument("hosts", nargs="+", help="host names")
    parser.add_argument("--domain", type=int, default=170, help="ROS_DOMAIN_ID of the hosts (default 170)")
    parser.add_argument("--delay-ms", type=float, help="impair the link: one-way delay per frame")
    parser.add_argument("--loss", type=float, help="impair the link: drop probability per frame")
    parser.add_argument("--seed", type=int, default=0, help="the impairment's RNG seed")
    args = parser.parse_args()
    impairment = None
    if args.delay_ms is not None or args.loss is not None:
        impairment = Impairment((args.delay_ms or 0.0) / 1e3, args.loss or 0.0, args.seed)
    reason = unavailable()
    if reason:
        raise SystemExit(reason)
    with Network(args.hosts, args.domain, impairment) as net:
        for host in net.hosts.values():
            env = " ".join(f"{k}={v}" for k, v in host.environment({}).items())
            print(f"{host.name}: {host.address} on {host.interface}; a shell in it:\n"
                  f"  env {env} {shlex.join(host.command(['bash']))}")
        print(f"link: {net.link}" + (f" ({impairment})" if impairment else "") + "; Ctrl-C ends it", flush=True)
        try:
            signal.pause()
        except KeyboardInterrupt:
            pass
        if impairment is not None:
            print(json.dumps(net.counters(), indent=1))


if __name__ == "__main__":
    main()

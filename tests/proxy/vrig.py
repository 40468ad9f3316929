"""The proxy on the virtual clock: the real Host over the in-process simulator, a fake sender.

`run_proxy(body)` starts a Host (with its engine) on a simulated hobby router in virtual time,
with a SenderProxy attached before the handshake and its forwarder running, and awaits
body(rig). The fake sender writes bytes into a connection and keeps everything it got.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import TypeVar

from smoothjog.host import Host
from smoothjog.links.sim import SimLink
from smoothjog.proxy import SenderConnection, SenderProxy
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.rig import LinkModel, SimRig
from smoothjog.vclock import VirtualClockLoop

T = TypeVar("T")

MACHINE = "hobby-router"


@dataclass
class FakeSender:
    """A sender on one connection: what it wrote goes in, everything it got is kept."""

    proxy: SenderProxy
    name: str = "fake"
    chunks: list[bytes] = field(default_factory=list)
    conn: SenderConnection | None = None

    def open(self, banner_delay_s: float = 0.0) -> FakeSender:
        self.conn = self.proxy.connect(self.chunks.append, self.name, banner_delay_s=banner_delay_s)
        return self

    def write(self, data: bytes | str) -> None:
        assert self.conn is not None
        self.conn.feed(data.encode("latin-1") if isinstance(data, str) else data)

    def lines(self) -> list[str]:
        """Every line received, in order, without its CR LF."""
        text = b"".join(self.chunks).decode("latin-1")
        assert text == "" or text.endswith("\r\n"), text[-40:]
        return text.split("\r\n")[:-1]

    def replies(self, since: int = 0) -> list[str]:
        """The ok/error lines among lines()[since:]."""
        return [x for x in self.lines()[since:] if x == "ok" or x.startswith("error:")]

    def non_reports(self, since: int = 0) -> list[str]:
        """lines()[since:] without the status reports."""
        return [x for x in self.lines()[since:] if not x.startswith("<")]

    async def wait_replies(self, n: int, since: int = 0, timeout_s: float = 5.0) -> list[str]:
        """Wait (virtual time) until n replies came after line index since."""
        async with asyncio.timeout(timeout_s):
            while len(self.replies(since)) < n:  # noqa: ASYNC110 - lines come by callback
                await asyncio.sleep(0.005)
        return self.replies(since)

    async def ask(self, line: str, timeout_s: float = 5.0) -> list[str]:
        """Send one line and wait for its reply; return what came (reports left out)."""
        since = len(self.lines())
        self.write(line + "\n")
        await self.wait_replies(1, since, timeout_s)
        return self.non_reports(since)


@dataclass
class ProxyRig:
    """One session: the rig, the link, the host and the proxy."""

    rig: SimRig
    link: SimLink
    host: Host
    proxy: SenderProxy

    def sender(self, name: str = "fake") -> FakeSender:
        return FakeSender(self.proxy, name).open()

    @property
    def firmware(self) -> GrblFirmware:
        return self.rig.firmware


def run_proxy(
    body: Callable[[ProxyRig], Awaitable[T]],
    *,
    machine: str = MACHINE,
    proxy: SenderProxy | None = None,
) -> T:
    """Run body against a started host + proxy on the virtual clock; close everything after."""
    loop = VirtualClockLoop()
    the_proxy = proxy if proxy is not None else SenderProxy()

    async def main() -> T:
        rig = SimRig(GrblFirmware(machine=machine), LinkModel())
        link = SimLink(rig=rig)
        await link.open()
        host = Host(link)
        the_proxy.attach(host)
        await host.start()
        the_proxy.started(host)
        forwarder = asyncio.create_task(the_proxy.run())
        try:
            return await body(ProxyRig(rig, link, host, the_proxy))
        finally:
            forwarder.cancel()
            await asyncio.gather(forwarder, return_exceptions=True)
            await host.close()

    try:
        return loop.run_until_complete(main())
    finally:
        loop.close()


def direct_replies(lines: list[bytes], *, machine: str = MACHINE) -> list[str]:
    """What the simulator itself answers to raw sender lines, each sent once the last is answered.

    The proxy must make the controller answer as it would have without it: tests compare.
    """
    rig = SimRig(GrblFirmware(machine=machine), LinkModel())
    t = 0.5
    rig.run_until(t)
    replies: list[str] = []
    for raw in lines:
        rig.host_send(raw, t)
        got: list[str] = []
        while not got:
            t += 0.01
            got = [
                line.decode("latin-1")
                for _at, line in rig.run_until(t)
                if line == b"ok" or line.startswith(b"error:")
            ]
        replies.extend(got)
    return replies

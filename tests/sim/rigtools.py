"""A tiny virtual-time host for the simulator tests: send bytes, run, collect replies."""

from __future__ import annotations

from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import get_firmware_profile, load_machine_profile
from smoothjog.sim.rig import LinkModel, SimRig


class Host:
    """Drives a SimRig like a sender would, in virtual time, and keeps every received line."""

    def __init__(
        self,
        firmware: str = "grbl",
        machine: str = "grbl-defaults",
        link: LinkModel | None = None,
    ) -> None:
        fw = GrblFirmware(get_firmware_profile(firmware), load_machine_profile(machine))
        self.rig = SimRig(fw, link)
        self.fw = fw
        self.received: list[tuple[float, str]] = []
        self.banner = self.until(lambda x: x.startswith(("Grbl", "GrblHAL")), 1.0)
        self.received.clear()  # the power-up banner is checked separately

    @property
    def now_s(self) -> float:
        return self.rig.now_s

    def send(self, data: bytes | str) -> None:
        """Write bytes now (a str is sent as ASCII, nothing appended)."""
        raw = data.encode("ascii") if isinstance(data, str) else data
        self.rig.host_send(raw, self.rig.now_s)

    def run(self, dt_s: float) -> list[str]:
        """Let dt_s pass; the lines that arrived meanwhile."""
        got = self.rig.run_until(self.rig.now_s + dt_s)
        lines = [(t, line.decode("ascii")) for t, line in got]
        self.received.extend(lines)
        return [text for _t, text in lines]

    def until(self, predicate: object, timeout_s: float = 5.0) -> list[str]:
        """Run until a received line satisfies predicate (a callable on str); the lines so far."""
        assert callable(predicate)
        deadline = self.rig.now_s + timeout_s
        lines: list[str] = []
        while self.rig.now_s < deadline:
            nxt = self.rig.next_event_s()
            step_to = deadline if nxt is None else min(max(nxt, self.rig.now_s), deadline)
            got = self.run(max(step_to - self.rig.now_s, 0.0))
            lines += got
            if any(predicate(line) for line in got):
                return lines
            if nxt is None:
                break
        return lines

    def command(self, line: str, timeout_s: float = 5.0) -> list[str]:
        """Send line + `\\n` and run until its ok/error; the lines received meanwhile."""
        self.send(line + "\n")
        return self.until(is_reply, timeout_s)

    def reply(self, line: str, timeout_s: float = 5.0) -> str:
        """The ok/error that answers line."""
        lines = self.command(line, timeout_s)
        replies = [x for x in lines if is_reply(x)]
        assert replies, f"no reply to {line!r}; got {lines}"
        return replies[-1]

    def status(self) -> str:
        """Send `?` and return the report."""
        self.send(b"?")
        lines = self.until(lambda x: x.startswith("<"), 1.0)
        reports = [x for x in lines if x.startswith("<")]
        assert reports, f"no status report; got {lines}"
        return reports[-1]

    def state(self) -> str:
        """The state field of a fresh status report."""
        return self.status()[1:].split("|", 1)[0]

    def wait_state(self, state: str, timeout_s: float = 30.0, poll_s: float = 0.05) -> None:
        """Poll until the report's state is state."""
        end = self.rig.now_s + timeout_s
        while self.rig.now_s < end:
            if self.state() == state:
                return
            self.run(poll_s)
        raise AssertionError(f"state never became {state}; last {self.status()}")


def is_reply(line: str) -> bool:
    """True for `ok` and `error:N`."""
    return line == "ok" or line.startswith("error:")


def field(report: str, name: str) -> str | None:
    """The value of one status-report field, or None."""
    for part in report.strip("<>").split("|")[1:]:
        key, _, value = part.partition(":")
        if key == name:
            return value
    return None


def mpos(report: str) -> tuple[float, ...]:
    """MPos of a report."""
    value = field(report, "MPos")
    assert value is not None, report
    return tuple(float(v) for v in value.split(","))

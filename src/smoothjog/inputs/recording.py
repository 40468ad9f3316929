"""Recorded device streams: what `jog --input-replay` and the tests read.

Two formats, both plain text, times in seconds:

evdev, as `evtest` prints it (the header is optional and gives the device's name, ids and
absolute ranges; without it the decoder's defaults apply):

    Input device ID: bus 0x3 vendor 0x45e product 0x2fd version 0x903
    Input device name: "Xbox Wireless Controller"
      Event type 3 (EV_ABS)
        Event code 0 (ABS_X)
          Value   4110
          Min   -32768
          Max    32767
          Fuzz     255
          Flat    4095
    Event: time 1550548790.247581, type 3 (EV_ABS), code 0 (ABS_X), value 6126
    Event: time 1550548790.247581, -------------- SYN_REPORT ------------

evtest marks lost events as `>>>>>>>>>>>>>> SYN_DROPPED <<<<<<<<<<<<`; that line, and a `#`
comment (a whole line, or after an Event line), are read too.

hidraw, one report per line: seconds since the start, then the report's bytes in hex (spaces
allowed); `#` starts a comment. hid-recorder's `E: SECONDS.MICROS LENGTH BYTES` lines (and its
`N:` name and `I:` bus/vendor/product lines) are read too.

    0.000  04 ba 00 00 0e 11 00 ba   # X at 0.01
    0.050  04 9d 00 00 0e 11 01 9c

Times are made relative to the first event, so a recording starts at 0 whatever clock it was
taken on.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from smoothjog.core.errors import SmoothjogError
from smoothjog.inputs.device import AbsRange, DeviceInfo, EvdevFrame, HidReport
from smoothjog.inputs.frames import FrameAssembler


class RecordingError(SmoothjogError):
    """A recording cannot be read; the message names the file and the line."""


@dataclass(frozen=True)
class EvdevRecording:
    """An evtest recording: the device as its header describes it, and its frames."""

    info: DeviceInfo
    frames: tuple[EvdevFrame, ...]
    #: SYN_DROPPED markers met (each replaced by a resync frame).
    dropped: int = 0


@dataclass(frozen=True)
class HidRecording:
    """A hidraw recording: the device (from hid-recorder's header, if any) and its reports."""

    info: DeviceInfo
    reports: tuple[HidReport, ...]


_EVENT = re.compile(
    r"^Event:\s*time\s+(?P<t>-?\d+(?:\.\d+)?),\s*"
    r"(?:type\s+(?P<type>\d+)\s*(?:\([^)]*\))?,\s*code\s+(?P<code>\d+)\s*(?:\([^)]*\))?,\s*"
    r"value\s+(?P<value>-?[0-9a-fA-F]+)|[-+>]+\s*(?P<syn>SYN_[A-Z_]+)\s*[-+<]+)\s*$"
)
_DEVICE_ID = re.compile(
    r"^Input device ID:\s*bus\s+0x(?P<bus>[0-9a-fA-F]+)\s+vendor\s+0x(?P<vendor>[0-9a-fA-F]+)"
    r"\s+product\s+0x(?P<product>[0-9a-fA-F]+)"
)
_DEVICE_NAME = re.compile(r'^Input device name:\s*"(?P<name>.*)"\s*$')
_TYPE = re.compile(r"^Event type\s+(?P<type>\d+)")
_CODE = re.compile(r"^Event code\s+(?P<code>\d+)")
_ABS_FIELD = re.compile(r"^(?P<field>Value|Min|Max|Fuzz|Flat|Resolution)\s+(?P<v>-?\d+)\s*$")
_SYN_CODES = {"SYN_REPORT": 0, "SYN_CONFIG": 1, "SYN_MT_REPORT": 2, "SYN_DROPPED": 3}
#: Header lines evtest prints that carry nothing a decoder needs.
_EVTEST_NOISE = (
    "Input driver version",
    "Supported events",
    "Properties",
    "Testing ...",
    "Repeat code",
    "Select the device",
    "Available devices",
    "/dev/input/",
    "Property type",
)


def _read(path: str | Path) -> tuple[str, str]:
    p = Path(path)
    try:
        return p.read_text(encoding="utf-8"), str(p)
    except FileNotFoundError:
        raise RecordingError(f"recording {p} does not exist: check the path") from None
    except IsADirectoryError:
        raise RecordingError(f"recording {p} is a directory: name a recording file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"cannot read recording {p}: {exc}") from None


def load_evtest(path: str | Path) -> EvdevRecording:
    """Read an evtest recording from a file."""
    text, source = _read(path)
    return parse_evtest(text.split("\n"), source=source)


def parse_evtest(lines: Iterable[str], *, source: str = "<evtest>") -> EvdevRecording:
    """Parse evtest's text: an optional device header, then Event lines."""
    name, bus, vendor, product = "recorded evdev device", 0, 0, 0
    ranges: dict[int, dict[str, int]] = {}
    keys: set[int] = set()
    rels: set[int] = set()
    current_type: int | None = None
    current_code: int | None = None
    assembler = FrameAssembler()
    frames: list[EvdevFrame] = []
    t0: float | None = None
    last_t = float("-inf")
    for number, raw in enumerate(lines, start=1):
        # A comment is a whole line, or follows an Event line (a device name may hold a #).
        stripped = raw.strip()
        if stripped.startswith("#"):
            continue
        line = stripped.split("#", 1)[0].strip() if stripped.startswith("Event:") else stripped
        if not line:
            continue
        where = f"{source}:{number}"
        if m := _EVENT.match(line):
            t = float(m["t"])
            if t < last_t:
                raise RecordingError(f"{where}: time {t} goes back before {last_t}")
            last_t = t
            if t0 is None:
                t0 = t
            rel_t = round(t - t0, 6)
            if m["syn"]:
                code = _SYN_CODES.get(m["syn"])
                if code is None:
                    continue
                frames.extend(assembler.feed(rel_t, 0, code, 0))
            else:
                type_ = int(m["type"])
                # evtest prints MSC_SCAN values in hex ("value 7005c"); every other value is a
                # decimal number. The scan codes are dropped by the frames anyway.
                base = 16 if type_ == 4 else 10
                try:
                    value = int(m["value"], base)
                except ValueError:
                    raise RecordingError(f"{where}: value {m['value']!r} is not a number") from None
                frames.extend(assembler.feed(rel_t, type_, int(m["code"]), value))
            continue
        if t0 is not None:
            raise RecordingError(
                f"{where}: expected an evtest 'Event: time ...' line, got {line[:60]!r}"
            )
        if m := _DEVICE_ID.match(line):
            bus, vendor, product = (int(m[k], 16) for k in ("bus", "vendor", "product"))
        elif m := _DEVICE_NAME.match(line):
            name = m["name"]
        elif line.startswith(("Key repeat handling", "Repeat type")):
            # The key-repeat block's "Value" lines are not an axis's range.
            current_type, current_code = None, None
        elif m := _TYPE.match(line):
            current_type, current_code = int(m["type"]), None
        elif m := _CODE.match(line):
            current_code = int(m["code"])
            if current_type == 1:
                keys.add(current_code)
            elif current_type == 2:
                rels.add(current_code)
        elif m := _ABS_FIELD.match(line):
            if current_type == 3 and current_code is not None:
                ranges.setdefault(current_code, {})[m["field"].lower()] = int(m["v"])
        elif not line.startswith(_EVTEST_NOISE):
            raise RecordingError(
                f"{where}: not an evtest line: {line[:60]!r} (expected the device header or "
                "'Event: time ...' lines)"
            )
    frames.extend(assembler.flush())
    if t0 is None:
        raise RecordingError(f"{source}: no 'Event: time ...' lines: nothing to replay")
    absinfo = {
        code: AbsRange(
            r.get("value", 0), r.get("min", 0), r.get("max", 0), r.get("fuzz", 0), r.get("flat", 0)
        )
        for code, r in ranges.items()
        if "min" in r and "max" in r
    }
    info = DeviceInfo(
        name=name,
        path=source,
        vendor=vendor,
        product=product,
        bus=bus,
        absinfo=absinfo,
        keys=frozenset(keys),
        rels=frozenset(rels),
    )
    return EvdevRecording(info, tuple(frames), assembler.dropped)


_HEX_LINE = re.compile(r"^(?P<t>\d+(?:\.\d+)?)\s+(?P<hex>[0-9a-fA-F][0-9a-fA-F\s]*)$")
_RECORDER_EVENT = re.compile(r"^E:\s*(?P<t>\d+(?:\.\d+)?)\s+(?P<n>\d+)\s*(?P<hex>[0-9a-fA-F\s]*)$")
_RECORDER_ID = re.compile(
    r"^I:\s*(?P<bus>[0-9a-fA-F]+)\s+(?P<vendor>[0-9a-fA-F]+)\s+(?P<product>[0-9a-fA-F]+)\s*$"
)


def load_hidraw(path: str | Path) -> HidRecording:
    """Read a hidraw recording from a file."""
    text, source = _read(path)
    return parse_hidraw(text.split("\n"), source=source)


def _hex_bytes(text: str, where: str) -> bytes:
    digits = "".join(text.split())
    if len(digits) % 2:
        raise RecordingError(f"{where}: odd number of hex digits ({len(digits)}): {text.strip()!r}")
    try:
        return bytes.fromhex(digits)
    except ValueError:
        raise RecordingError(f"{where}: not hex bytes: {text.strip()!r}") from None


def parse_hidraw(lines: Iterable[str], *, source: str = "<hidraw>") -> HidRecording:
    """Parse `SECONDS HEX` lines (or hid-recorder's E: lines) into timed reports."""
    name, bus, vendor, product = "recorded hidraw device", 0, 0, 0
    reports: list[HidReport] = []
    t0: float | None = None
    last_t = float("-inf")
    for number, raw in enumerate(lines, start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        where = f"{source}:{number}"
        data: bytes
        if line.startswith("N:"):
            name = line[2:].strip() or name
            continue
        if m := _RECORDER_ID.match(line):
            bus, vendor, product = (int(m[k], 16) for k in ("bus", "vendor", "product"))
            continue
        if line.startswith(("R:", "P:", "D:")):
            continue  # descriptor, physical path, device number: not needed to decode
        if m := _RECORDER_EVENT.match(line):
            data = _hex_bytes(m["hex"], where)
            if len(data) != int(m["n"]):
                raise RecordingError(f"{where}: the line says {m['n']} bytes but holds {len(data)}")
        elif m := _HEX_LINE.match(line):
            data = _hex_bytes(m["hex"], where)
        else:
            raise RecordingError(
                f"{where}: expected 'SECONDS HEX BYTES' (e.g. 0.016 04 ba 00 00 0e 11 00 ba), "
                f"got {line[:60]!r}"
            )
        if not data:
            raise RecordingError(f"{where}: a report needs at least one byte")
        t = float(m["t"])
        if t < last_t:
            raise RecordingError(f"{where}: time {t} goes back before {last_t}; sort the lines")
        last_t = t
        if t0 is None:
            t0 = t
        reports.append(HidReport(round(t - t0, 6), data))
    if not reports:
        raise RecordingError(f"{source}: no reports: nothing to replay")
    info = DeviceInfo(name=name, path=source, vendor=vendor, product=product, bus=bus)
    return HidRecording(info, tuple(reports))

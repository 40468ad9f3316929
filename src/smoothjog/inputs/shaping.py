"""From raw axis values to stick deflections in [-1, 1]: centring, deadzone, expo, clamping.

The kernel reports each absolute axis with its own range and rest value, which differ by driver
for the same pad (-32768..32767 under xpad, 0..65535 under hid-generic, 0..255 centred on 128
under hid-playstation), and it does not clamp values to that range. So every value is
normalised from the axis's own range first, then shaped:

1. centre and half range from min and max (a one-sided axis, a trigger, maps min..max to 0..1);
2. a deadzone that is rescaled, so the output leaves 0 continuously at the deadzone's edge
   instead of jumping to the deadzone's value; for a stick pair the deadzone is radial (on the
   length of the (x, y) vector), so a diagonal is not cut more than an axis;
3. expo: y = (1 - k) x + k x^3 keeps full speed at full deflection and gives fine control near
   the centre;
4. clamp to [-1, 1] (real devices overshoot their declared range).
"""

from __future__ import annotations

import math

from smoothjog.inputs.device import AbsRange


def clamp_unit(x: float) -> float:
    """x limited to [-1, 1] (NaN becomes 0)."""
    if math.isnan(x):
        return 0.0
    return max(-1.0, min(1.0, x))


def normalise(value: int, rng: AbsRange, *, one_sided: bool = False) -> float:
    """A raw value as -1..1 about the middle of rng (0..1 from min for a one-sided axis)."""
    span = rng.max - rng.min
    if span <= 0:
        return 0.0
    if one_sided:
        return max(0.0, min(1.0, (value - rng.min) / span))
    centre = (rng.max + rng.min) / 2.0
    offset = value - centre
    # An even range (-32768..32767) has its centre between two values; both read as the
    # centre, so a stick at rest on the other axis adds no hair of motion to a jog.
    if abs(offset) <= 0.5:
        return 0.0
    return clamp_unit(offset / (span / 2.0))


def deadzone(x: float, dz: float) -> float:
    """One axis: 0 inside dz, rescaled so |x| = dz..1 maps to 0..1."""
    if dz <= 0.0:
        return clamp_unit(x)
    mag = abs(x)
    if mag <= dz:
        return 0.0
    return math.copysign(min(1.0, (mag - dz) / (1.0 - dz)), x)


def radial_deadzone(x: float, y: float, dz: float) -> tuple[float, float]:
    """A stick pair: 0 inside the circle of radius dz, the length rescaled outside it."""
    r = math.hypot(x, y)
    if r <= dz or r == 0.0:
        return 0.0, 0.0
    scale = min(1.0, (r - dz) / (1.0 - dz)) / r if dz > 0.0 else min(1.0, r) / r
    return clamp_unit(x * scale), clamp_unit(y * scale)


def expo(x: float, k: float) -> float:
    """The expo curve (1 - k) x + k x^3, k in [0, 1]; odd, monotonic, expo(±1) = ±1."""
    return clamp_unit((1.0 - k) * x + k * x * x * x)

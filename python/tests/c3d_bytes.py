"""C3D files written byte by byte (Intel): the header and each parameter set apart, for
files whose header and parameters disagree, as no writer of a package makes them."""

import struct

import numpy as np


def i16(group, name, *values):
    """An integer parameter of `group` (1 POINT, 2 ANALOG, 3 TRIAL)."""
    dims = [] if len(values) == 1 else [len(values)]
    return group, name, bytes([2, len(dims), *dims]) + struct.pack(f"<{len(values)}H", *values)


def f32(group, name, value):
    """A float parameter."""
    return group, name, bytes([4, 0]) + struct.pack("<f", value)


def strings(group, name, values):
    """A character parameter of `values`, padded to the longest."""
    n = max(1, *(len(v) for v in values))
    data = b"".join(v.ljust(n).encode() for v in values)
    return group, name, bytes([0xFF, 2, n, len(values)]) + data


def trial(first, last):
    """TRIAL:ACTUAL_START_FIELD and ACTUAL_END_FIELD, each as two 16-bit words."""
    return [i16(3, "ACTUAL_START_FIELD", first & 0xFFFF, first >> 16),
            i16(3, "ACTUAL_END_FIELD", last & 0xFFFF, last >> 16)]


def point_params(labels, rate=100.0, scale=-0.1, analog_used=0, analog_rate=None):
    """POINT:USED, SCALE, RATE, LABELS, DESCRIPTIONS, UNITS and ANALOG:USED, RATE."""
    return [i16(1, "USED", len(labels)), f32(1, "SCALE", scale), f32(1, "RATE", rate),
            strings(1, "LABELS", labels), strings(1, "DESCRIPTIONS", [""] * len(labels)),
            strings(1, "UNITS", ["mm"]), i16(2, "USED", analog_used),
            f32(2, "RATE", analog_rate or rate)]


def write(path, points, params, *, header=None, rate=100.0, scale=-0.1, analog=None):
    """Writes `points` ([T, N, 4] float: x, y, z and the residual word) and `analog` ([T, A]
    words after each frame's points) as an Intel float file. `header`: words (1-based) set
    over the plain ones, which say what the data hold."""
    t, n, _ = points.shape
    a = 0 if analog is None else analog.shape[1]
    section = bytearray([1, 0x50, 0, 84])
    entries = [(-1, "POINT", b""), (-2, "ANALOG", b""), (-3, "TRIAL", b"")] + list(params)
    for i, (group, name, body) in enumerate(entries):
        section += bytes([len(name), group & 0xFF]) + name.encode()
        last = i == len(entries) - 1
        if group < 0:
            section += struct.pack("<H", 0 if last else 3) + b"\0"
        else:
            section += struct.pack("<H", 0 if last else 2 + len(body) + 1) + body + b"\0"
    blocks = -(-len(section) // 512)
    section += bytes(blocks * 512 - len(section))
    section[2] = blocks
    words = {2: n, 3: a, 4: 1, 5: min(t, 65535), 9: 2 + blocks, 10: 1}
    words.update(header or {})
    head = bytearray(512)
    head[0], head[1] = 2, 0x50
    for w, v in words.items():
        head[2 * (w - 1):2 * w] = struct.pack("<H", v)
    head[12:16] = struct.pack("<f", scale)
    head[20:24] = struct.pack("<f", rate)
    body = points.astype("<f4").reshape(t, -1)
    if analog is not None:
        body = np.concatenate([body, analog.astype("<f4")], axis=1)
    data = body.tobytes()
    data += bytes(-len(data) % 512)
    with open(path, "wb") as h:
        h.write(bytes(head) + bytes(section) + data)

#!/usr/bin/env python3
"""Writes the binary seeds of tests/fuzz/corpus (klg/, exr/, png/): tiny
files made here from scratch with the standard library, valid ones and
near-valid ones (truncated, a wrong size, a corrupt stream). The text seeds
of the other targets are written by hand; the EXR seeds of other
compressions and layouts (openexr_*.exr) by make_exr_seeds.cpp through
OpenEXR. Run from anywhere; it rewrites the files it owns and leaves the
others alone."""
import os
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
W, H = 4, 3  # the camera baked into fuzz_klg.cpp


def put(target, name, data):
    path = os.path.join(HERE, "corpus", target, name)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "wb") as f:
        f.write(data)


# ---- .klg: int32 count, then per frame int64 us, int32 depth size, int32
# colour size, depth bytes (raw uint16 LE or zlib), colour bytes.
def depth_bytes(base):
    return b"".join(struct.pack("<H", (base + 37 * k) % 4000 if k % 5 else 0) for k in range(W * H))


def frame(us, depth, colour=b""):
    return struct.pack("<qii", us, len(depth), len(colour)) + depth + colour


def klg(frames, count=None):
    return struct.pack("<i", len(frames) if count is None else count) + b"".join(frames)


raw_colour = bytes((17 * k) % 256 for k in range(W * H * 3))
fake_jpeg = bytes([0xFF, 0xD8, 0xFF, 0xE0, 0, 16]) + b"JFIF\0" + bytes(9) + bytes([0xFF, 0xD9])
put("klg", "raw_two_frames.klg", klg([frame(1000, depth_bytes(500), raw_colour), frame(34333, depth_bytes(600))]))
put("klg", "zlib_three_frames.klg",
    klg([frame(0, zlib.compress(depth_bytes(800))), frame(33333, zlib.compress(depth_bytes(900), 9), fake_jpeg),
         frame(66666, depth_bytes(1000), raw_colour)]))
put("klg", "one_frame_no_colour.klg", klg([frame(-5, depth_bytes(0))]))
put("klg", "count_too_large.klg", klg([frame(1, depth_bytes(1)), frame(2, depth_bytes(2))], count=3))
put("klg", "trailing_bytes.klg", klg([frame(1, depth_bytes(1))], count=1) + b"\0\0\0")
put("klg", "truncated_zlib.klg", klg([frame(1, zlib.compress(depth_bytes(3))[:-4])]))
put("klg", "zlib_too_long.klg", klg([frame(1, zlib.compress(depth_bytes(3) + b"\1\2"))]))
put("klg", "timestamps_not_increasing.klg", klg([frame(5, depth_bytes(1)), frame(5, depth_bytes(2))]))


# ---- OpenEXR: single-part scanline images with the attributes read_exr needs.
def attribute(name, kind, value):
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value


def exr(channels, compression, window=(0, 0, W - 1, H - 1), values=None, extra=b""):
    """channels: [(name, type)] with type 1 = HALF, 2 = FLOAT; compression 0 NONE, 2 ZIPS, 3 ZIP."""
    x0, y0, x1, y1 = window
    width, height = x1 - x0 + 1, y1 - y0 + 1
    chlist = b"".join(n.encode() + b"\0" + struct.pack("<iB3xii", t, 0, 1, 1) for n, t in channels) + b"\0"
    header = struct.pack("<II", 20000630, 2)
    header += attribute("channels", "chlist", chlist)
    header += attribute("compression", "compression", bytes([compression]))
    header += attribute("dataWindow", "box2i", struct.pack("<iiii", x0, y0, x1, y1))
    header += attribute("displayWindow", "box2i", struct.pack("<iiii", x0, y0, x1, y1))
    header += attribute("lineOrder", "lineOrder", b"\0")
    header += attribute("pixelAspectRatio", "float", struct.pack("<f", 1.0))
    header += extra + b"\0"
    lines = 16 if compression == 3 else 1
    chunks = []
    for first in range(0, height, lines):
        block = b""
        for y in range(first, min(first + lines, height)):
            for c, (_, t) in enumerate(channels):
                for x in range(width):
                    v = values(x, y, c) if values else 0.5 + 0.25 * x + 0.125 * y + c
                    block += struct.pack("<e" if t == 1 else "<f", v)
        if compression != 0:
            n = len(block)
            half = (n + 1) // 2
            coded = bytearray(n)
            for k in range(n):
                coded[k // 2 if k % 2 == 0 else half + k // 2] = block[k]
            for k in range(n - 1, 0, -1):
                coded[k] = (coded[k] - coded[k - 1] + 128) % 256
            packed = zlib.compress(bytes(coded))
            if len(packed) < n:
                block = packed
        chunks.append(struct.pack("<ii", y0 + first, len(block)) + block)
    table_end = len(header) + 8 * len(chunks)
    offsets, pos = b"", table_end
    for c in chunks:
        offsets += struct.pack("<Q", pos)
        pos += len(c)
    return header + offsets + b"".join(chunks)


put("exr", "float_none.exr", exr([("Z", 2)], 0))
put("exr", "half_zips.exr", exr([("Z", 1)], 2))
put("exr", "rgb_zip_offset_window.exr", exr([("B", 1), ("G", 1), ("R", 2)], 3, window=(-2, 5, 5, 24)))
put("exr", "layer_depth_nan.exr",
    exr([("view.Depth", 2), ("view.mask", 1)], 2, values=lambda x, y, c: float("nan") if x == y else -1.0 * c))
put("exr", "truncated.exr", exr([("Z", 2)], 3)[:-7])
put("exr", "tiled_attribute.exr", exr([("Z", 2)], 0, extra=attribute("tiles", "tiledesc", bytes(9))))


# ---- PNG: grayscale 1/8/16-bit, RGB, palette; an interlaced one; a corrupt one.
def chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


ADAM7 = [(0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2)]


def png(width, height, depth, colour, rows, interlace=0, extra=b""):
    """rows: filter-less scanlines; with interlace=1, 8-bit one-byte pixels split into the Adam7 passes."""
    ihdr = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, interlace)
    if interlace:
        rows = [bytes(rows[y][x] for x in range(x0, width, dx))
                for x0, y0, dx, dy in ADAM7 if x0 < width for y in range(y0, height, dy)]
    raw = b"".join(b"\0" + r for r in rows)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + extra + chunk(b"IDAT", zlib.compress(raw)) +
            chunk(b"IEND", b""))


put("png", "gray8.png", png(W, H, 8, 0, [bytes((y * 40 + x * 9) % 256 for x in range(W)) for y in range(H)]))
put("png", "gray16.png", png(W, H, 16, 0, [b"".join(struct.pack(">H", 1000 * y + 7 * x) for x in range(W))
                                           for y in range(H)]))
put("png", "gray1.png", png(9, 2, 1, 0, [bytes([0b10110010, 0b10000000]), bytes([0b01001101, 0])]))
put("png", "rgb8.png", png(W, H, 8, 2, [bytes((x * 30 + y * 50 + c * 70) % 256 for x in range(W) for c in range(3))
                                        for y in range(H)]))
put("png", "palette_trns.png", png(3, 2, 8, 3, [bytes([0, 1, 2]), bytes([2, 1, 0])],
                                   extra=chunk(b"PLTE", bytes([255, 0, 0, 0, 255, 0, 0, 0, 255])) +
                                   chunk(b"tRNS", bytes([128]))))
put("png", "gray8_interlaced.png", png(5, 5, 8, 0, [bytes(range(y * 5, y * 5 + 5)) for y in range(5)], interlace=1))
put("png", "truncated.png", png(W, H, 8, 0, [bytes(W)] * H)[:-20])

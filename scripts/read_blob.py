#!/usr/bin/python3
"""Reads a palpa field blob (v1 or v2) by docs/blob-format.md alone, with numpy only.

An independent second reader: it shares no code with palpa, so when it agrees with
`palpa export` on every voxel the spec is enough to read a blob.

    /usr/bin/python3 scripts/read_blob.py FIELD.palpa [--npy OUT.npy] [--compare EXPORT.npy]

--npy writes φ in metres, float32, shape (nx, ny, nz), C order (what `palpa export` writes: v2
values clamped to ±max(band_inside, band_outside), the dense equivalent of docs/blob-format.md).
--compare loads an export and exits 1 unless every voxel is bit-identical.
Errors (a blob that breaks the spec) name the field and byte offset; exit code 2.
"""
import argparse
import struct
import sys

import numpy as np


class BlobError(Exception):
    pass


def crc32c(data: bytes, crc: int = 0) -> int:
    """CRC-32C (Castagnoli), reflected polynomial 0x82F63B78, init and final xor 0xFFFFFFFF."""
    table = crc32c.table
    crc ^= 0xFFFFFFFF
    for b in data:
        crc = table[(crc ^ b) & 0xFF] ^ (crc >> 8)
    return crc ^ 0xFFFFFFFF


def _make_table():
    t = []
    for i in range(256):
        c = i
        for _ in range(8):
            c = (0x82F63B78 ^ (c >> 1)) if c & 1 else c >> 1
        t.append(c)
    return t


crc32c.table = _make_table()


def fail(field, offset, msg):
    raise BlobError(f"{field} at byte {offset}: {msg}")


def read_v1(b: bytes):
    if len(b) < 144:
        fail("header", len(b), "truncated")
    nx, ny, nz = struct.unpack_from("<3I", b, 16)
    (voxel,) = struct.unpack_from("<d", b, 56)
    (payload_size,) = struct.unpack_from("<Q", b, 120)
    (crc,) = struct.unpack_from("<I", b, 140)
    if payload_size != 4 * nx * ny * nz or len(b) != 144 + payload_size:
        fail("payload_size", 120, "does not match dims and file length")
    if crc32c(b[144:], crc32c(b[:140])) != crc:
        fail("crc32c", 140, "mismatch")
    q16 = np.frombuffer(b, dtype="<i4", count=nx * ny * nz, offset=144).reshape(nx, ny, nz)
    (band,) = struct.unpack_from("<I", b, 64)
    return q16.astype(np.int64), voxel, band


def read_v2(b: bytes):
    if len(b) < 168:
        fail("header", len(b), "truncated")
    nx, ny, nz = struct.unpack_from("<3I", b, 16)
    (value_format,) = struct.unpack_from("<I", b, 28)
    if value_format != 2:
        fail("value_format", 28, f"{value_format}, expected 2")
    (voxel,) = struct.unpack_from("<d", b, 56)
    bnx, bny, bnz = struct.unpack_from("<3I", b, 120)
    if (bnx, bny, bnz) != tuple((n + 7) // 8 for n in (nx, ny, nz)):
        fail("brick_dims", 120, "not ceil(dims / 8)")
    brick_count, octant_count = struct.unpack_from("<2I", b, 132)
    octants_offset, payload_size = struct.unpack_from("<2Q", b, 144)
    (crc,) = struct.unpack_from("<I", b, 164)
    slots = bnx * bny * bnz
    tables_at = 168 + 4 * slots
    if octants_offset != (tables_at + 32 * brick_count + 63) // 64 * 64:
        fail("octants_offset", 144, "not align64(168 + 4*slots + 32*brick_count)")
    if payload_size != octants_offset - 168 + 128 * octant_count or len(b) != 168 + payload_size:
        fail("payload_size", 152, "does not match the counts and file length")
    if crc32c(b[168:], crc32c(b[:164])) != crc:
        fail("crc32c", 164, "mismatch")
    index = np.frombuffer(b, dtype="<u4", count=slots, offset=168).reshape(bnx, bny, bnz)
    tables = np.frombuffer(b, dtype="<u4", count=8 * brick_count, offset=tables_at).reshape(brick_count, 2, 2, 2)
    octants = np.frombuffer(b, dtype="<i2", count=64 * octant_count, offset=octants_offset).reshape(
        octant_count, 4, 4, 4)

    def uniform_phi(e):  # the low 16 bits as int16
        return np.int64(np.uint16(e & 0xFFFF).view(np.int16))

    grid = np.zeros((8 * bnx, 8 * bny, 8 * bnz), dtype=np.int64)  # Q7.8, padded to whole bricks
    for bi in range(bnx):
        for bj in range(bny):
            for bk in range(bnz):
                e = int(index[bi, bj, bk])
                brick = grid[8 * bi:8 * bi + 8, 8 * bj:8 * bj + 8, 8 * bk:8 * bk + 8]
                if e & 0x80000000:
                    brick[...] = uniform_phi(e)
                    continue
                if e >= brick_count:
                    fail("index", 168 + 4 * ((bi * bny + bj) * bnz + bk), "brick number out of range")
                for ox in range(2):
                    for oy in range(2):
                        for oz in range(2):
                            t = int(tables[e, ox, oy, oz])
                            o = brick[4 * ox:4 * ox + 4, 4 * oy:4 * oy + 4, 4 * oz:4 * oz + 4]
                            if t & 0x80000000:
                                o[...] = uniform_phi(t)
                            elif t < octant_count:
                                o[...] = octants[t]
                            else:
                                fail("tables", tables_at + 32 * e + 4 * (4 * ox + 2 * oy + oz), "octant out of range")
    (band_inside, band_outside) = struct.unpack_from("<2I", b, 64)
    return grid[:nx, :ny, :nz] * 256, voxel, max(band_inside, band_outside)  # Q7.8 → Q16.16


def read_blob(path):
    with open(path, "rb") as f:
        b = f.read()
    if len(b) < 12 or b[:8] != b"PALPASDF":
        fail("magic", 0, "not a palpa field blob")
    (version,) = struct.unpack_from("<H", b, 8)
    if version == 1:
        return read_v1(b)
    if version == 2:
        return read_v2(b)
    fail("version", 8, f"{version} is not supported")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("blob")
    ap.add_argument("--npy")
    ap.add_argument("--compare")
    a = ap.parse_args()
    try:
        q16, voxel, band = read_blob(a.blob)
    except BlobError as e:
        print(f"read_blob.py: {a.blob}: {e}", file=sys.stderr)
        return 2
    # φ in metres as palpa export writes it: the dense equivalent (values clamped to ±band, the
    # larger of v2's two bands), then float32(double(q16) / 65536 · voxel).
    dense = np.clip(q16, -band * 65536, band * 65536)
    metres = (dense.astype(np.float64) / 65536.0 * voxel).astype(np.float32)
    print(f"{a.blob}: dims {q16.shape}, voxel {voxel * 1e3:.6f} mm, "
          f"φ in [{q16.min() / 65536.0:.4f}, {q16.max() / 65536.0:.4f}] voxels")
    if a.npy:
        np.save(a.npy, metres)
    if a.compare:
        other = np.load(a.compare)
        if other.shape != metres.shape or other.dtype != np.float32:
            print(f"read_blob.py: shape/dtype differ: {other.shape} {other.dtype}", file=sys.stderr)
            return 1
        diff = np.flatnonzero(metres.view(np.uint32) != other.view(np.uint32))
        if diff.size:
            n = np.unravel_index(diff[0], metres.shape)
            print(f"read_blob.py: {diff.size} voxels differ, first at {tuple(int(x) for x in n)}: "
                  f"{metres[n]} vs {other[n]}", file=sys.stderr)
            return 1
        print(f"agrees with {a.compare} on all {metres.size} voxels")
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/python3
"""Blob v2 through the CLI (issue 7), on bundled data at the default settings.

    blob_cli_test.py PALPA WORKDIR sizes     # bytes per stored voxel <= 2.5 and <= 8 % of dense
                                             # float32, kitten and sphere926 at 300 cells
    blob_cli_test.py PALPA WORKDIR reader    # scripts/read_blob.py agrees with palpa export on
                                             # every voxel (v2 default, v2 asymmetric, v1)
"""
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def run(*args):
    r = subprocess.run(args, capture_output=True, text=True)
    if r.returncode != 0:
        print(r.stdout, r.stderr, file=sys.stderr)
        raise SystemExit(f"failed: {' '.join(args)}")
    return r.stdout


def build(palpa, work, name, src, *extra):
    out = os.path.join(work, name + ".palpa")
    run(palpa, "build", os.path.join(ROOT, "data", src), "-o", out, "-q", *extra)
    return out


def sizes(palpa, work):
    ok = True
    for name, src in (("kitten", "kitten.xyz"), ("sphere926", "sphere926.pwn")):
        info = json.loads(run(palpa, "info", build(palpa, work, name, src), "--json"))
        per, pct = info["bytes_per_stored_voxel"], info["percent_of_dense_float32"]
        print(f"{name}: v{info['format_version']}, {info['blob_bytes']} bytes, {per:.3f} bytes/stored voxel, "
              f"{pct:.2f} % of dense float32, zstd {info['zstd_bytes']} bytes")
        if info["format_version"] != 2 or per > 2.5 or pct > 8.0:
            print(f"{name}: over the issue 7 bounds (2.5 bytes/stored voxel, 8 %)", file=sys.stderr)
            ok = False
    return ok


def reader(palpa, work):
    ok = True
    for name, src, extra in (("kitten-c120", "kitten.xyz", ("--cells", "120")),
                             ("oni-c80-b4-o3", "oni.pwn", ("--cells", "80", "--band", "4", "--band-outside", "3")),
                             ("sphere926-c60-v1", "sphere926.pwn", ("--cells", "60", "--format", "1"))):
        blob = build(palpa, work, name, src, *extra)
        npy = os.path.join(work, name + ".npy")
        run(palpa, "export", blob, "--npy", npy)
        r = subprocess.run(["/usr/bin/python3", os.path.join(ROOT, "scripts", "read_blob.py"), blob, "--compare", npy],
                           capture_output=True, text=True)
        print(r.stdout.strip(), r.stderr.strip())
        ok = ok and r.returncode == 0 and "agrees" in r.stdout
    return ok


if __name__ == "__main__":
    palpa, work, what = sys.argv[1:4]
    os.makedirs(work, exist_ok=True)
    sys.exit(0 if {"sizes": sizes, "reader": reader}[what](palpa, work) else 1)

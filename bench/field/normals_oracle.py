#!/usr/bin/python3
"""Which estimated normals decide a stripped row (issue 20; docs/field-methods.md § Normals stripped:
what the three misses are made of):

    bench/field/normals_oracle.py [--palpa build/host/host/cli/palpa] [--work DIR] [--cells 150]
                                  [--seed 21] [--meshes spool,couplingdown,rotor,/path/other.off]

For each closed mesh, `palpa sample -n 5000 --seed S` draws exact oriented samples (as
robustness.py). Their normals are stripped, and `palpa build --points-out` estimates and orients
new ones. Every written sample is matched to its exact normal, then the set is rebuilt with
`--normals keep` (the default) after giving back the exact normal to some samples only:

  - none: the estimated set as written (the samples the build ignored are not in it);
  - all:   every sample whose estimate is more than --off degrees from the exact normal;
  - signs: only the sign, where the estimate points inward (the line kept);
  - lines: only the line, where it is more than --off degrees off (the estimate's sign kept);
  - drop:  the samples more than --off degrees off left out instead.

Each build is scored with `palpa eval --mesh` (wrong sign in the band, %, and far-wrong nodes), and
the exact normals on the same samples give the reference. A row whose `all` column meets the
target while `none` does not is decided by those few samples; `signs` and `lines` say which kind of
error it is. Uses Debian's python3-numpy and python3-scipy (scripts/install-deps).
"""
import argparse
import os

import numpy as np
from scipy.spatial import cKDTree

from robustness import Unsampled, draw, run, score  # the same draw, build and score as the table's


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--palpa", default="build/host/host/cli/palpa")
    ap.add_argument("--work", default="build/normals-oracle")
    ap.add_argument("--cells", type=int, default=150)
    ap.add_argument("--seed", type=int, default=21)
    ap.add_argument("--off", type=float, default=30.0, help="degrees: an estimate this far off is given back")
    ap.add_argument("--meshes", default="spool,couplingdown,rotor",
                    help="bundled mesh names (data/NAME.off) or paths to closed .off meshes, comma-separated")
    args = ap.parse_args()
    os.makedirs(args.work, exist_ok=True)
    print(f"| mesh | samples off > {args.off:g}° / wrong sign | exact normals | none | all | signs | lines | drop |")
    print("|---|---|---|---|---|---|---|---|")
    for name in args.meshes.split(","):
        try:
            mesh, name, exact_path = draw(args.palpa, name, args.seed, args.work)
        except Unsampled as e:
            print(f"| skipped: {e} |")
            continue
        exact = np.loadtxt(exact_path)
        bare = os.path.join(args.work, f"{name}-bare.xyz")
        np.savetxt(bare, exact[:, :3], fmt="%.9g")
        estimated_path = os.path.join(args.work, f"{name}-estimated.xyz")
        run(args.palpa, "build", bare, "-o", os.path.join(args.work, "probe.palpa"), "--cells", str(args.cells),
            "--format", "1", "-q", "--points-out", estimated_path)
        est = np.loadtxt(estimated_path)
        # --points-out keeps the positions as read: each written sample is one of the exact ones.
        distance, index = cKDTree(exact[:, :3]).query(est[:, :3])
        if distance.max() > 1e-6 * np.ptp(exact[:, :3], axis=0).max():
            raise SystemExit(f"{name}: a written sample is not one of the drawn ones ({distance.max():g} off)")
        truth = exact[index, 3:]
        cos = np.clip(np.einsum("ij,ij->i", truth, est[:, 3:]), -1.0, 1.0)
        off = np.degrees(np.arccos(cos)) > args.off
        line_off = np.degrees(np.arccos(np.abs(cos))) > args.off
        inward = cos < 0

        def variant(tag, normals, keep=None):
            pts = np.hstack([est[:, :3], normals])
            if keep is not None:
                pts = pts[keep]
            path = os.path.join(args.work, f"{name}-{tag}.xyz")
            np.savetxt(path, pts, fmt="%.9g")
            _, r = score(args.palpa, args.palpa, path, mesh, args.cells, args.work)
            return f"{r['wrong']:.2f} % / {r['far']}"

        cells = [variant("exact", truth), variant("none", est[:, 3:])]
        given = est[:, 3:].copy()
        given[off] = truth[off]
        cells.append(variant("all", given))
        signs = est[:, 3:].copy()
        signs[inward] *= -1.0
        cells.append(variant("signs", signs))
        lines = est[:, 3:].copy()
        lines[line_off] = truth[line_off] * np.sign(cos[line_off])[:, None]
        cells.append(variant("lines", lines))
        cells.append(variant("drop", est[:, 3:], keep=~off))
        print(f"| {name} | {off.sum()} / {inward.sum()} of {len(est)} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()

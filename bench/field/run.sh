#!/usr/bin/env bash
# Field build speed and scale (issue 5), every figure in one run so that ratios are fair:
#   bench/field/run.sh [BUILD_DIR [--dense]]   (default build/field-bench; Release)
# Builds `palpa` and the field benchmarks, then runs bench/field/measure.py, which prints:
#   - whole `palpa build data/kitten.xyz` at 150, 300, 600 and 1,200 cells: wall time and peak
#     RSS (/usr/bin/time -v), blob size, time(600)/time(300), time(1200)/time(600);
#   - `palpa mesh` and `palpa export --npy` of the 1,200-cell blob: wall, peak RSS, output size;
#   - scipy.ndimage.distance_transform_edt alone on the 300-cell grid, alternated with palpa's
#     300-cell build at least 5 times, and the ratio of the minima and the median of the pairs;
#   - palpa build at 300 cells with 1 and 2 TBB threads;
#   - stage times (packing, patches, centre tests, evaluation, projection) at 150/300/600 cells;
#   - packing (eq. 2-3) on cube.pwn: k-d tree (50,000 points; 1 and 2 threads) and brute force
#     on 5,000 points;
#   - with --dense: 2,000,000 samples at 300 cells, knot1 oriented and fandisk without normals,
#     wall, peak RSS and the ratio to the kitten's 300-cell build (issue 20).
# The load average before and after is printed: compare ratios, and rerun when it is high.
set -euo pipefail
cd "$(dirname "$0")/../.."
build=${1:-build/field-bench}
shift || true

cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$build" --target palpa >/dev/null
# The benchmarks: from the tree if bench/CMakeLists.txt lists field/, else configured on their own.
if cmake --build "$build" --target palpa_field_bench palpa_field_stages >/dev/null 2>&1; then
  bench_bin="$build/bench/field"
else
  cmake -S bench/field -B "$build/bench-field" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
  cmake --build "$build/bench-field" >/dev/null
  bench_bin="$build/bench-field"
fi
exec /usr/bin/python3 bench/field/measure.py --palpa "$build/host/cli/palpa" --bench-bin "$bench_bin" \
  --work "$build/bench-field-out" "$@"

#!/usr/bin/env bash
# End-to-end browser test of `palpa view` (ctest label `browser`, docs/view.md): builds the
# kitten field at default settings, replays a synthesised stroke through palpad on the simulated
# device, serves it with `palpa view --trace`, and drives Debian's headless Chromium with
# playwright-core (view_test.mjs). With the status channel built, it also follows a paced
# `palpad --device sim --listen` with `palpa view --connect`.
# Usage: run_view_test.sh PALPA PALPAD WEB_DIR OUT_DIR
set -euo pipefail
palpa=$1 palpad=$2 web=$3 out=$4
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$out"
rm -f "$out"/*.png

for need in node /usr/bin/chromium "$web/node_modules/playwright-core/package.json" "$web/node_modules/pngjs/package.json"; do
  if ! command -v "$need" >/dev/null 2>&1 && [ ! -e "$need" ]; then
    echo "browser test: $need is missing: run scripts/install-deps (installs chromium and runs npm ci in web/)" >&2
    exit 1
  fi
done

pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
}
trap cleanup EXIT

"$palpa" build "$here/../../data/kitten.xyz" -o "$out/kitten.palpa" -q
"$palpa" trace synth --field "$out/kitten.palpa" --kind stroke -o "$out/stroke.csv" >/dev/null
"$palpad" --device sim --field "$out/kitten.palpa" --trace "$out/stroke.csv" --out "$out/forces.csv" --fast >/dev/null
"$palpa" mesh "$out/kitten.palpa" -o "$out/kitten.ply" -q

# Starts `palpa view ARGS...` on a free loopback port and sets $url. Runs in this shell, not in a
# $(...) subshell, so that its pid reaches `pids` and the EXIT trap stops it.
start_view() {
  local log=$1
  shift
  url=""
  "$palpa" view "$@" --bind 127.0.0.1:0 >"$log.out" 2>"$log.err" &
  pids+=($!)
  for _ in $(seq 1 300); do
    if grep -q 'http://' "$log.out" 2>/dev/null; then
      url=$(grep -o 'http://[^ ]*' "$log.out")
      return 0
    fi
    if ! kill -0 "${pids[-1]}" 2>/dev/null; then break; fi
    sleep 0.1
  done
  echo "browser test: palpa view did not start:" >&2
  cat "$log.err" >&2
  return 1
}

start_view "$out/view-replay" "$out/kitten.palpa" --trace "$out/forces.csv"
replay_url=$url

cd "$web"
node "$here/view_test.mjs" --replay "$replay_url" --csv "$out/forces.csv" --ply "$out/kitten.ply" --out "$out"

# Live: palpa keygen, palpad --listen and the status-channel client are part of every build, so
# the live checks always run (a missing piece fails the test, never skips it).
rm -f "$out/status.key"
"$palpa" keygen -o "$out/status.key" >/dev/null
# A paced run of a slow stroke (about 80 s; stopped when the test ends), so the tick counter
# still advances once the page has loaded, even on a loaded machine.
"$palpa" trace synth --field "$out/kitten.palpa" --kind stroke --speed 0.0005 -o "$out/live.csv" >/dev/null
"$palpad" --device sim --field "$out/kitten.palpa" --trace "$out/live.csv" --out /dev/null \
  --listen 127.0.0.1:0 --key-file "$out/status.key" 2>"$out/palpad-live.err" >/dev/null &
pids+=($!)
endpoint=""
for _ in $(seq 1 100); do
  endpoint=$(grep -o 'listening on [^ ]*' "$out/palpad-live.err" 2>/dev/null | cut -d' ' -f3 || true)
  [ -n "$endpoint" ] && break
  sleep 0.1
done
if [ -z "$endpoint" ]; then
  echo "browser test: palpad --listen did not report its port:" >&2
  cat "$out/palpad-live.err" >&2
  exit 1
fi
start_view "$out/view-live" "$out/kitten.palpa" --connect "$endpoint" --key-file "$out/status.key" || exit 1
node "$here/view_test.mjs" --live "$url" --out "$out"

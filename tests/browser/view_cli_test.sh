#!/usr/bin/env bash
# `palpa view` and `palpa bench latency --with-viewer` as a user runs them: exit codes and messages
# for bad input, a non-loopback warning, the page served, a clean stop on SIGTERM, and the
# benchmark printing both rows (no timing assertion: figures are for benchmarks, not tests).
# Usage: view_cli_test.sh PALPA PALPAD WORK_DIR
set -uo pipefail
palpa=$1 palpad=$2 work=$3
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$work"
fail=0
expect() {  # expect CODE PATTERN -- command...
  local code=$1 pattern=$2
  shift 3
  local out rc
  out=$("$@" 2>&1)
  rc=$?
  if [ "$rc" != "$code" ] || ! grep -q -- "$pattern" <<<"$out"; then
    echo "FAIL: $* -> exit $rc (want $code), output: $out (want /$pattern/)"
    fail=1
  else
    echo "PASS: $* -> $code, /$pattern/"
  fi
}

# A small field: the sphere of 926 points, 64 cells.
"$palpa" build "$here/../../data/sphere926.pwn" -o "$work/sphere.palpa" --cells 64 -q || exit 1
printf 't_s,hip_x_m\n0,1\n' >"$work/bad.csv"
printf 't_s,hip_x_m,hip_y_m,hip_z_m,proxy_x_m,proxy_y_m,proxy_z_m,fx_n,fy_n,fz_n,contact\n0,0,0,0,0,0,zz,0,0,0,0\n' >"$work/bad2.csv"

expect 2 "missing.palpa" -- "$palpa" view "$work/missing.palpa"
expect 2 "bad.csv:1: expected palpad's CSV header" -- "$palpa" view "$work/sphere.palpa" --trace "$work/bad.csv"
expect 2 "bad2.csv:2: field 7 'zz' is not a finite number" -- "$palpa" view "$work/sphere.palpa" --trace "$work/bad2.csv"
expect 2 "expects HOST:PORT" -- "$palpa" view "$work/sphere.palpa" --bind nonsense
expect 2 "expects HOST:PORT" -- "$palpa" view "$work/sphere.palpa" --bind 127.0.0.1:99999
expect 2 "needs --key-file" -- "$palpa" view "$work/sphere.palpa" --connect 127.0.0.1:1
expect 2 "no-such.key" -- "$palpa" view "$work/sphere.palpa" --connect 127.0.0.1:1 --key-file "$work/no-such.key"
expect 1 "no index.html" -- "$palpa" view "$work/sphere.palpa" --assets "$work"

# Serves on any address only when asked, with a warning; stops cleanly on SIGTERM.
"$palpa" view "$work/sphere.palpa" --bind 0.0.0.0:0 >"$work/any.out" 2>"$work/any.err" &
pid=$!
for _ in $(seq 1 100); do grep -q http "$work/any.out" && break; sleep 0.1; done
url=$(grep -o 'http://[^ ]*' "$work/any.out")
if grep -q "not loopback" "$work/any.err" && [ "$(/usr/bin/python3 -c 'import sys, urllib.request; print(urllib.request.urlopen(sys.argv[1]).status)' "$url")" = 200 ]; then
  echo "PASS: --bind 0.0.0.0:0 warns and serves $url"
else
  echo "FAIL: --bind 0.0.0.0:0: $(cat "$work/any.err")"
  fail=1
fi
kill -TERM "$pid"
wait "$pid"
rc=$?
if [ "$rc" = 0 ]; then echo "PASS: SIGTERM stops palpa view with exit 0"; else echo "FAIL: SIGTERM -> exit $rc"; fail=1; fi

# The latency benchmark with a viewer attached: both rows, and the viewer's polls.
out=$("$palpa" bench latency --with-viewer --seconds 1 --rounds 1 --no-cyclictest --palpad "$palpad" 2>&1)
if grep -q "palpad, no viewer" <<<"$out" && grep -q "palpad + palpa view" <<<"$out" &&
  grep -Eq "made [1-9][0-9]* status requests" <<<"$out"; then
  echo "PASS: bench latency --with-viewer prints both rows"
else
  echo "FAIL: bench latency --with-viewer: $out"
  fail=1
fi
exit $fail

#!/usr/bin/env bash
# Builds the Debian packages of a configured and built tree with cpack and checks them with
# dpkg-deb: package names, architecture, shlibdeps-computed Depends, and the installed paths.
# usage: check_deb.sh BUILD_DIR ARCH COMPONENT...   (exit 77 = skipped: the tree is missing)
set -euo pipefail
build=$1 arch=$2
shift 2
if [ ! -f "$build/CPackConfig.cmake" ]; then
  if [ "${PALPA_NO_CROSS:-0}" = 1 ]; then echo "skipped: $build not built (PALPA_NO_CROSS=1)"; exit 77; fi
  echo "FAIL: $build/CPackConfig.cmake missing (configure and build that preset first)"; exit 1
fi
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
(cd "$build" && cpack -G DEB -B "$out" > "$out/cpack.log" 2>&1) || { cat "$out/cpack.log"; exit 1; }
fail=0
check() { if ! grep -q -- "$2" <<<"$1"; then echo "FAIL: $3"; fail=1; fi; }
for comp in "$@"; do
  deb=$(ls "$out"/"${comp}"_*_"$arch".deb 2>/dev/null | head -1)
  if [ -z "$deb" ]; then echo "FAIL: no ${comp}_*_${arch}.deb in:"; ls "$out"; exit 1; fi
  info=$(dpkg-deb -I "$deb")
  files=$(dpkg-deb -c "$deb")
  echo "== $(basename "$deb")"; grep -E '^ (Package|Architecture|Depends):' <<<"$info"
  check "$info" "Package: $comp" "$deb: package name"
  check "$info" "Architecture: $arch" "$deb: architecture"
  check "$info" "Depends:.*libc6" "$deb: Depends from dpkg-shlibdeps"
  check "$files" "./usr/bin/$comp\$" "$deb: /usr/bin/$comp"
  if [ "$comp" = palpad ]; then
    check "$files" "./usr/lib/systemd/system/palpad.service" "$deb: systemd unit"
    check "$files" "./etc/default/palpad" "$deb: /etc/default/palpad"
    check "$files" "./etc/palpa/palpad.toml" "$deb: example config /etc/palpa/palpad.toml"
    check "$info" "Depends:.*libgpiod2" "$deb: Depends on libgpiod2 (GPIO e-stop and tick line)"
    # Control files and the unit, unpacked: conffiles, and the service reading the config.
    ctl="$out/ctl-$arch" root="$out/root-$arch"
    dpkg-deb -e "$deb" "$ctl" && dpkg-deb -x "$deb" "$root"
    check "$(cat "$ctl/conffiles" 2>/dev/null)" "^/etc/palpa/palpad.toml\$" "$deb: palpad.toml is a conffile"
    check "$(cat "$ctl/conffiles" 2>/dev/null)" "^/etc/default/palpad\$" "$deb: /etc/default/palpad is a conffile"
    unit=$(cat "$root/usr/lib/systemd/system/palpad.service")
    check "$unit" "^ExecStart=/usr/bin/palpad --config /etc/palpa/palpad.toml " "$deb: unit runs palpad --config"
    check "$unit" "^LimitRTPRIO=" "$deb: unit allows SCHED_FIFO"
    check "$unit" "^LimitMEMLOCK=infinity" "$deb: unit allows mlockall"
    check "$unit" "^RuntimeDirectory=palpa" "$deb: unit creates /run/palpa for the status"
    # The shipped config parses with the shipped palpad (native packages only: no emulator here).
    if [ "$arch" = "$(dpkg --print-architecture)" ]; then
      if ! checked=$("$root/usr/bin/palpad" --config "$root/etc/palpa/palpad.toml" --check-config 2>&1); then
        echo "FAIL: $deb: the shipped config does not parse: $checked"; fail=1
      fi
      check "$checked" '^device = "falcon"' "$deb: --check-config prints the shipped config"
    fi
  fi
done
exit $fail

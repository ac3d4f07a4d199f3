#!/usr/bin/env bash
# Install the Debian packages the test-suite needs beyond PyPI, if missing.
# Never fails the build: tests that need a missing tool skip with a reason.
set -u
pkgs=(gcc-avr avr-libc binutils-avr simavr libsimavr-dev libsimavrparts1 libelf-dev pkg-config libosmesa6)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
if ! command -v apt-get >/dev/null 2>&1; then
  echo "system-deps: apt-get not available; missing: ${missing[*]} (firmware tests will be skipped)" >&2
  exit 0
fi
SUDO=""
[ "$(id -u)" -ne 0 ] && command -v sudo >/dev/null 2>&1 && SUDO="sudo -n"
echo "system-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
{ $SUDO apt-get update -qq && $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"; } >/tmp/system-deps.log 2>&1 \
  || echo "system-deps: apt-get install failed (see /tmp/system-deps.log); dependent tests will be skipped" >&2
exit 0

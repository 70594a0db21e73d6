#!/usr/bin/env bash
# Headless Chromium for the viewer's browser tests (tests/test_viewer_browser.py) and the browser
# run of benchmarks/bench_viewer.py.
#
# The tests drive Debian's `chromium` package through Playwright for Python with
# `executable_path=/usr/bin/chromium`: Playwright's own browser download (`playwright install`)
# needs hosts this project's machines cannot reach, and a distribution package is kept patched.
# `fonts-dejavu-core` gives the page's text a font in headless mode.
#
# Usage: scripts/install_browser.sh [--optional]
#   --optional  never fail (used by `make test`): report what could not be installed and exit 0,
#               so the browser tests skip with a reason instead.
# Debian/Ubuntu (apt-get) only; elsewhere install Chromium by hand and set SPLINECAST_CHROMIUM
# to its executable.
set -uo pipefail

optional=0
[[ "${1:-}" == "--optional" ]] && optional=1

packages=(chromium fonts-dejavu-core)

fail() {
    echo "install_browser.sh: $*" >&2
    if (( optional )); then
        echo "install_browser.sh: continuing without it; browser tests of the viewer will skip" >&2
        exit 0
    fi
    exit 1
}

if ! command -v dpkg-query >/dev/null 2>&1 || ! command -v apt-get >/dev/null 2>&1; then
    fail "not a Debian-based system; install Chromium by hand"
fi

missing=()
for p in "${packages[@]}"; do
    # Installed already -> nothing to do; this keeps repeated `make test` runs offline and fast.
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$p")
    fi
done
if (( ${#missing[@]} == 0 )); then
    echo "install_browser.sh: chromium already installed"
    exit 0
fi

sudo=()
if (( EUID != 0 )); then
    if command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
        sudo=(sudo -n)
    else
        fail "need root (or passwordless sudo) to install: ${missing[*]}"
    fi
fi

echo "install_browser.sh: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${sudo[@]}" apt-get update -qq || fail "apt-get update failed"
"${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" \
    || fail "apt-get install ${missing[*]} failed"
echo "install_browser.sh: done"

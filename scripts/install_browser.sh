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

script=install_browser.sh
skip_note="browser tests of the viewer will skip"
elsewhere="install Chromium by hand"
already="chromium already installed"
# shellcheck source=apt_install.sh
source "$(dirname "${BASH_SOURCE[0]}")/apt_install.sh"
apt_install

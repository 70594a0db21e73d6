#!/usr/bin/env bash
# Tools for benchmarks/profile_kernel.py (instruction-level profiles of the compiled kernels):
#
#   linux-perf   perf record / perf script (sampled instruction addresses; the cpu-clock event
#                works in virtual machines without hardware counters)
#   binutils     objdump (disassembles the kernel's machine code copied from the process)
#
# Usage: scripts/install_profiling.sh [--optional]
#   --optional  never fail: report what could not be installed and exit 0.
# Debian/Ubuntu (apt-get) only; on other systems install perf and objdump by hand.
set -uo pipefail

optional=0
[[ "${1:-}" == "--optional" ]] && optional=1

packages=(linux-perf binutils)

script=install_profiling.sh
skip_note="benchmarks/profile_kernel.py will not run"
elsewhere="install perf and objdump by hand"
already="perf and objdump already installed"
# shellcheck source=apt_install.sh
source "$(dirname "${BASH_SOURCE[0]}")/apt_install.sh"
apt_install

#!/usr/bin/env bash
# System libraries for offscreen VTK rendering (the comparison suite, benchmarks/compare.py).
#
# The PyPI vtk wheels (>= 9.4) pick their OpenGL window at run time: X11 when a display exists,
# otherwise EGL (vtkEGLRenderWindow) or OSMesa (vtkOSOpenGLRenderWindow). Neither needs a GPU: with
# Mesa both run on the llvmpipe software rasterizer. Those classes dlopen the system's libEGL /
# libOSMesa, which the wheel does not ship, so a machine without a display or GPU needs:
#
#   libosmesa6       libOSMesa.so.8    (vtkOSOpenGLRenderWindow, Mesa's offscreen software GL)
#   libegl1          libEGL.so.1       (glvnd EGL loader, vtkEGLRenderWindow)
#   libegl-mesa0     Mesa's EGL vendor library (surfaceless platform)
#   libgl1-mesa-dri  the swrast/llvmpipe driver EGL loads
#   libgbm1          buffer manager Mesa's EGL links against
#   libxrender1 libxt6 libx11-6  X libraries the wheel's modules link against even offscreen
#
# Usage: scripts/install_bench.sh [--optional]
#   --optional  never fail: report what could not be installed and exit 0. (`make test` runs the
#               strict form and treats a failure as optional itself, so it can retry next time.)
# Debian/Ubuntu (apt-get) only; on other systems install the same libraries by hand.
set -uo pipefail

optional=0
[[ "${1:-}" == "--optional" ]] && optional=1

packages=(libosmesa6 libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1 libxrender1 libxt6 libx11-6)

fail() {
    echo "install_bench.sh: $*" >&2
    if (( optional )); then
        echo "install_bench.sh: continuing without them; VTK comparison tests will skip" >&2
        exit 0
    fi
    exit 1
}

if ! command -v dpkg-query >/dev/null 2>&1 || ! command -v apt-get >/dev/null 2>&1; then
    fail "not a Debian-based system; install OSMesa or EGL (Mesa) libraries by hand"
fi

missing=()
for p in "${packages[@]}"; do
    # Installed already -> nothing to do; this keeps repeated `make test` runs offline and fast.
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$p")
    fi
done
if (( ${#missing[@]} == 0 )); then
    echo "install_bench.sh: system libraries for offscreen VTK already installed"
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

echo "install_bench.sh: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${sudo[@]}" apt-get update -qq || fail "apt-get update failed"
"${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" \
    || fail "apt-get install ${missing[*]} failed"
echo "install_bench.sh: done"

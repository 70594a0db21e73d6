# shellcheck shell=bash
# Shared by the install_*.sh scripts (sourced, not run): install the Debian packages named in the
# array `packages` unless they are installed already, with apt-get (as root or passwordless sudo).
#
# The sourcing script sets, before calling `apt_install`:
#   script     its name, for the messages
#   optional   1: report what could not be installed and exit 0 (the dependent tests skip)
#   skip_note  what happens without the packages (printed with --optional)
#   elsewhere  what to do on a system without apt-get
#   already    the message when nothing is missing

fail() {
    echo "$script: $*" >&2
    if (( optional )); then
        echo "$script: continuing without them; $skip_note" >&2
        exit 0
    fi
    exit 1
}

apt_install() {
    if ! command -v dpkg-query >/dev/null 2>&1 || ! command -v apt-get >/dev/null 2>&1; then
        fail "not a Debian-based system; $elsewhere"
    fi

    local missing=() p
    for p in "${packages[@]}"; do
        # Installed already -> nothing to do; this keeps repeated `make test` runs offline and fast.
        if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
            missing+=("$p")
        fi
    done
    if (( ${#missing[@]} == 0 )); then
        echo "$script: $already"
        exit 0
    fi

    local sudo=()
    if (( EUID != 0 )); then
        if command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
            sudo=(sudo -n)
        else
            fail "need root (or passwordless sudo) to install: ${missing[*]}"
        fi
    fi

    echo "$script: installing ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    "${sudo[@]}" apt-get update -qq || fail "apt-get update failed"
    "${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" \
        || fail "apt-get install ${missing[*]} failed"
    echo "$script: done"
}

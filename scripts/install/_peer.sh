# Shared by the scripts/install/install_*.sh that install a real peer from Debian's packages
# (sourced, never run). A script sets PEER (its name in messages), PKGS (the Debian packages)
# and defines two functions:
#   present   cheap: are the packages there (dpkg-query) and their files in place?
#   works     the peer used for real (a roscore that answers, a page rendered, a program
#             compiled and linked), printing why when it does not: run on every call
# and optionally APT_FLAGS (default --no-install-recommends), then calls `peer_install`.
# Its exit status tells the truth: 0 and "PEER: ready (...)" only
# when the peer works; otherwise 1 and "PEER: unavailable: REASON" (not root, no apt-get, an
# apt-get that failed or timed out, packages installed but not working). Bounded: each
# apt-get has a timeout and waits at most 600 s for another apt-get's lock. Idempotent: a
# second run finds the peer present and returns at once.

peer_ready() { echo "$PEER: ready ($*)"; exit 0; }
peer_unavailable() { echo "$PEER: unavailable: $*"; exit 1; }

dpkg_have() {  # dpkg_have PKG...: every package is installed
    local p
    for p in "$@"; do
        dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed" || return 1
    done
}

peer_install() {
    local why
    if present; then
        why="$(works 2>&1)" || peer_unavailable "installed, but it does not work: $why"
        peer_ready "already installed"
    fi
    [ "$(id -u)" = 0 ] || peer_unavailable "not root: as root, run bash ${BASH_SOURCE[1]} (apt-get install $PKGS)"
    command -v apt-get >/dev/null 2>&1 || peer_unavailable "no apt-get (not a Debian system): install $PKGS by hand"
    export DEBIAN_FRONTEND=noninteractive
    local apt=(apt-get -o DPkg::Lock::Timeout=600 -o Acquire::Retries=2)
    # shellcheck disable=SC2086  # PKGS is a list of names
    if ! timeout 1200 "${apt[@]}" install -y -qq ${APT_FLAGS---no-install-recommends} $PKGS >/dev/null 2>&1; then
        timeout 600 "${apt[@]}" update -qq >/dev/null 2>&1 \
            || peer_unavailable "apt-get update failed or timed out (no package index?)"
        # shellcheck disable=SC2086
        timeout 1200 "${apt[@]}" install -y -qq ${APT_FLAGS---no-install-recommends} $PKGS >/dev/null 2>&1 \
            || peer_unavailable "apt-get install $PKGS failed or timed out"
    fi
    present || peer_unavailable "apt-get install $PKGS ran, but the packages or their files are missing"
    why="$(works 2>&1)" || peer_unavailable "installed, but it does not work: $why"
    peer_ready "installed"
}

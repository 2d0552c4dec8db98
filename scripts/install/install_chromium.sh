#!/usr/bin/env bash
# Install Debian's headless-capable Chromium for the browser tests (tests/test_docs.py,
# tests/view/). Exits 0 only when headless Chromium renders a page (its DOM dumped with a
# script's output in it); otherwise 1 with the reason (scripts/install/_peer.sh). Idempotent and
# bounded in time. No network: the page is a data: URL and every background service is off.
set -u
PEER="chromium"
PKGS="chromium"
# shellcheck source=scripts/install/_peer.sh
. "$(dirname "${BASH_SOURCE[0]}")/_peer.sh"
present() { dpkg_have $PKGS && command -v chromium >/dev/null 2>&1; }
works() {
    local dir out rc
    dir="$(mktemp -d)"
    out="$(TMPDIR="$dir" timeout 60 chromium --headless --no-sandbox --disable-gpu --disable-quic \
        --no-first-run --disable-background-networking --disable-component-update \
        --disable-sync --user-data-dir="$dir" --dump-dom \
        'data:text/html,<p id="p"></p><script>document.getElementById("p").textContent="rendered-"+(6*7)</script>' \
        2>/dev/null)"
    rc=$?
    rm -rf "$dir"
    [ $rc -eq 0 ] || { echo "headless chromium exited with $rc"; return 1; }
    case "$out" in *rendered-42*) return 0 ;; esac
    echo "headless chromium did not render a page"
    return 1
}
peer_install

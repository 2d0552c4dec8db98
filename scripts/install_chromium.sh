#!/usr/bin/env bash
# Install Debian's headless-capable Chromium for tests/test_docs.py (renders the built
# documentation site). Idempotent and time-bounded; exits 0 with a reason on stdout
# when the install is impossible (not root, no apt-get), so the test can skip with it.
set -u
if command -v chromium >/dev/null 2>&1; then
    echo "chromium: already installed ($(command -v chromium))"
    exit 0
fi
if [ "$(id -u)" != 0 ]; then
    echo "chromium: not installed and not root (run: apt-get install chromium)"
    exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
    echo "chromium: not installed and apt-get is absent (not a Debian system)"
    exit 0
fi
export DEBIAN_FRONTEND=noninteractive
# Another apt-get may be running (other installs on this machine): wait for its lock.
if ! apt-cache policy chromium 2>/dev/null | grep -q 'Candidate: [0-9]'; then
    timeout 600 apt-get -o DPkg::Lock::Timeout=600 update -qq >/dev/null 2>&1 \
        || echo "chromium: apt-get update failed or timed out"
fi
if timeout 1200 apt-get -o DPkg::Lock::Timeout=600 install -y -qq --no-install-recommends \
        chromium >/dev/null 2>&1 && command -v chromium >/dev/null 2>&1; then
    echo "chromium: installed ($(command -v chromium))"
else
    echo "chromium: apt-get install chromium failed or timed out"
fi
exit 0

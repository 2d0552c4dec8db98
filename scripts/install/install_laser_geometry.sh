#!/usr/bin/env bash
# Install ROS 1 laser_geometry (C++ headers + library, Python bindings) from Debian, for
# the differential tests in tests/sensors/test_laser.py. Exits 0 only when a program using
# laser_geometry::LaserProjection compiles, links and runs, and the Python module imports;
# otherwise 1 with the reason (scripts/install/_peer.sh). Idempotent and bounded in time.
set -u
PEER="laser_geometry"
PKGS="liblaser-geometry-dev python3-laser-geometry g++ pkg-config"
# shellcheck source=scripts/install/_peer.sh
. "$(dirname "${BASH_SOURCE[0]}")/_peer.sh"
present() {
    # shellcheck disable=SC2086
    dpkg_have $PKGS && command -v g++ >/dev/null && pkg-config --exists laser_geometry
}
works() {
    local dir rc
    dir="$(mktemp -d)"
    printf '%s\n' '#include <laser_geometry/laser_geometry.h>' \
        'int main() { laser_geometry::LaserProjection p; (void)p; return 0; }' > "$dir/check.cpp"
    # shellcheck disable=SC2046
    timeout 300 g++ -std=c++17 -o "$dir/check" "$dir/check.cpp" \
        $(pkg-config --cflags --libs laser_geometry) && timeout 60 "$dir/check" \
        && /usr/bin/python3 -c "import laser_geometry"
    rc=$?
    rm -rf "$dir"
    return $rc
}
peer_install

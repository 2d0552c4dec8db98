"""``project_laser`` has two paths, the compiled projector (``tfbus._claser``, used with
the compiled core) and numpy (pure-Python installs, ``TFBUS_PURE_PYTHON``); both must give
the same cloud byte for byte, for any ranges (NaN, ±inf, below range_min, beyond the
cutoff), any channel options, with and without intensities, and when one projector sees
scans of several geometries in turn (its co-sine table is copied when the geometry
changes). The numbers themselves are checked against C++ laser_geometry in
``test_laser.py``."""

from __future__ import annotations

import numpy as np
import pytest

from tfbus import Header, Time
from tfbus.core import COMPILED
from tfbus.laser import LaserProjection
from tfbus.sensor_msgs import LaserScan, PointCloud2

pytestmark = pytest.mark.skipif(
    not COMPILED, reason="the compiled projector is used with the compiled core only"
)


def _cloud_fields(cloud: PointCloud2) -> tuple[object, ...]:
    return (cloud.header, cloud.height, cloud.width, cloud.fields, cloud.is_bigendian,
            cloud.point_step, cloud.row_step, cloud.data, cloud.is_dense)  # fmt: skip


def _scan(rng: np.random.Generator, n: int, intensities: bool, geometry: int) -> LaserScan:
    ranges = (rng.random(n) * 35.0 - 2.0).astype(np.float32)
    kind = rng.random(n)
    ranges[kind < 0.05] = np.nan
    ranges[(kind >= 0.05) & (kind < 0.1)] = np.inf
    ranges[(kind >= 0.1) & (kind < 0.12)] = -np.inf
    return LaserScan(
        header=Header(Time(5, 250), "base_laser"),
        angle_min=-3.0 + 0.5 * geometry, angle_max=3.0, angle_increment=0.001 + 0.004 * geometry,
        time_increment=float(rng.uniform(0.0, 1e-4)), scan_time=0.1,
        range_min=float(rng.uniform(0.0, 1.0)), range_max=float(rng.uniform(5.0, 30.0)),
        ranges=ranges,
        intensities=rng.random(n).astype(np.float32) if intensities else np.zeros(0, np.float32),
    )  # fmt: skip


def test_the_compiled_projector_is_in_use() -> None:
    assert LaserProjection()._projector is not None


@pytest.mark.parametrize("seed", range(6))
def test_compiled_and_numpy_paths_give_the_same_cloud(seed: int) -> None:
    rng = np.random.default_rng(seed)
    compiled, numpy_path = LaserProjection(), LaserProjection()
    numpy_path._projector = None
    for k in range(40):
        n = int(rng.integers(0, 1500)) if k % 10 else 0
        scan = _scan(rng, n, intensities=bool(k % 3), geometry=k % 4)
        opts = int(rng.integers(0, 32))
        cutoff = -1.0 if k % 2 else float(rng.uniform(0.0, 40.0))
        want = numpy_path.project_laser(scan, cutoff, opts)
        got = compiled.project_laser(scan, cutoff, opts)
        assert _cloud_fields(got) == _cloud_fields(want), (seed, k, n, opts, cutoff)


def test_short_intensities_are_refused_on_both_paths() -> None:
    rng = np.random.default_rng(9)
    scan = _scan(rng, 10, intensities=True, geometry=0)
    scan.intensities = scan.intensities[:5]
    numpy_path = LaserProjection()
    numpy_path._projector = None
    for projection in (LaserProjection(), numpy_path):
        with pytest.raises(ValueError, match="intensities has 5 values for 10 ranges"):
            projection.project_laser(scan, -1.0, 1)


@pytest.mark.parametrize("intensities", [True, False])
def test_scans_whose_every_beam_is_kept_give_the_same_cloud(intensities: bool) -> None:
    """Every beam kept (the usual scan: no resize of the cloud's bytes), in every layout."""
    rng = np.random.default_rng(11)
    compiled, numpy_path = LaserProjection(), LaserProjection()
    numpy_path._projector = None
    for opts in range(32):
        scan = _scan(rng, 721, intensities=intensities, geometry=opts % 4)
        scan.ranges = rng.uniform(scan.range_min, scan.range_max, 721).astype(np.float32)
        scan.ranges[0] = np.float32(scan.range_min)  # the lower bound is kept
        want = numpy_path.project_laser(scan, -1.0, opts)
        got = compiled.project_laser(scan, -1.0, opts)
        assert got.width == 721
        assert _cloud_fields(got) == _cloud_fields(want), opts


def test_clouds_cut_to_their_kept_beams_are_whole_objects() -> None:
    """A cloud whose bytes were cut to the kept beams owns them: they keep their value
    after later projections (which allocate and cut clouds of their own)."""
    rng = np.random.default_rng(12)
    projection = LaserProjection()
    scans = [_scan(rng, 300, intensities=True, geometry=0) for _ in range(20)]
    clouds = [projection.project_laser(scan) for scan in scans]
    copies = [bytes(bytearray(cloud.data)) for cloud in clouds]
    for scan in scans:
        projection.project_laser(scan)
    assert all(cloud.width < 300 for cloud in clouds)
    assert [cloud.data for cloud in clouds] == copies
    assert all(len(c.data) == c.width * c.point_step for c in clouds)

"""Run evo's own ``evo_traj`` command line (evo from PyPI, GPL-3.0, installed by
``scripts/install/install_evo.sh``, not copied), on real tf2 or on tfbus.compat.

Usage: ``python evo_runner.py EVO_DIR (debian|tfbus) EVO_TRAJ_ARGS...``

* ``debian``: nothing is changed; evo's ``tf_cache`` imports Debian's ``tf2_py`` (run it
  with Debian's ``/usr/bin/python3``).
* ``tfbus``: before evo is imported, ``sys.modules["tf2_py"]`` is set to
  ``tfbus.compat.tf2_py`` -- evo's ``import tf2_py`` (its only tf2 import: ``BufferCore``,
  ``LookupException``, ``ExtrapolationException``, ``TransformException``) then gets
  tfbus's. Everything else evo imports (``geometry_msgs.msg``, ``rclpy.time``) is the
  interpreter's own: run it with the ROS 2 venv's python.

``EVO_DIR`` goes first on ``sys.path`` for ``debian`` (Debian's numpy 1.24 is older than
the numpy evo's scipy needs: evo's own, installed beside it, is used) and last for
``tfbus`` (the venv's own numpy, which tfbus was built with). Exits with evo's status.
"""

from __future__ import annotations

import sys


def main() -> int:
    evo_dir, side, *args = sys.argv[1:]
    if side == "tfbus":
        sys.path.append(evo_dir)
        import tfbus.compat.tf2_py

        sys.modules["tf2_py"] = tfbus.compat.tf2_py
    elif side == "debian":
        sys.path.insert(0, evo_dir)
    else:
        raise SystemExit(f"side must be 'debian' or 'tfbus', got {side!r}")
    sys.argv = ["evo_traj", *args]
    from evo.cli.entry_points import traj  # type: ignore[import-not-found]

    traj()
    return 0


if __name__ == "__main__":
    sys.exit(main())

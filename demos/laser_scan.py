"""The tutorial's robot with a simulated 40 Hz laser: scans through a MessageFilter,
projected into odom three ways, wall error against the known room printed each second.

    python demos/laser_scan.py --duration 10        # or: tfbus demo laser

Read `tfbus/demo_laser.py` for the nodes.
"""

import sys

from tfbus.demo_laser import main

if __name__ == "__main__":
    sys.exit(main())

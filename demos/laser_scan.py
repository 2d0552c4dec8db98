"""The tutorial's robot with a simulated 40 Hz laser: scans through a MessageFilter,
projected into odom three ways, wall error against the known room printed each second.

    python demos/laser_scan.py --duration 10        # or: tfbus demo laser --duration 10

Read `tfbus/demos/laser.py` for the nodes. The options are `tfbus demo laser`'s (this
script runs that command).
"""

import sys

from tfbus.cli import main

if __name__ == "__main__":
    sys.exit(main(["demo", "laser", *sys.argv[1:]]))

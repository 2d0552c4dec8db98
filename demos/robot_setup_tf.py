"""ROS's "Setting up your robot using tf" tutorial, on a tfbus bus, in one process.

    python demos/robot_setup_tf.py --duration 10        # or: tfbus demo / make demo
    python demos/robot_setup_tf.py listener             # the tutorial's terminals, over Zenoh
    python demos/robot_setup_tf.py broadcaster

A 100 Hz broadcaster publishes base_link -> base_laser (10 cm forward, 20 cm up); a 1 Hz
listener transforms the laser point (1.0, 0.2, 0.0) into base_link and prints the
tutorial's line. The two nodes are `tfbus.demos.tutorial.broadcaster_node` and
`tfbus.demos.tutorial.listener_node`; read `tfbus/demos/tutorial.py` for their ten lines
each. The options are `tfbus demo`'s (this script runs that command).
"""

import sys

from tfbus.cli import main

if __name__ == "__main__":
    sys.exit(main(["demo", *sys.argv[1:]]))

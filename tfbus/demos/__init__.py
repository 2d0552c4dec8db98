"""The demo nodes behind ``tfbus demo`` (options are parsed by :mod:`tfbus.cli.demo` only).

* :mod:`tfbus.demos.tutorial` — ROS's "Setting up your robot using tf" tutorial: a 100 Hz
  broadcaster and a 1 Hz listener, in one process or as the tutorial's separate nodes;
* :mod:`tfbus.demos.laser` — the tutorial's robot with a simulated laser, its scans
  projected through a :class:`~tfbus.filters.MessageFilter` three ways.

The scripts in the repository's ``demos/`` folder run the same ``tfbus demo`` command.
"""

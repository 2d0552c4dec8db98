"""Run code written against tf2's Python APIs on tfbus, unchanged but for the imports.

* :mod:`tfbus.compat.tf2_py`: ``BufferCore`` with every method of Debian's ``tf2_py``
  0.7.6 (``can_transform_core``, ``lookup_transform_core``, ``_chain``, ...) and ROS 2
  tf2_py's ``lookupVelocityCore`` / ``lookupVelocityFullCore``.
* :mod:`tfbus.compat.tf2_ros`: ``Buffer`` with ROS 2 tf2_ros's call shapes (and
  awaitable ``*_async`` methods whose timeouts work), ``TransformListener`` (an rclpy
  node's ``/tf`` or a tfbus bus), the broadcasters, tf2's exceptions, the registries.

Adapters only: arguments are converted (:mod:`tfbus.compat._args`: rospy / rclpy /
builtin_interfaces times and durations, geometry messages duck-typed on their fields)
and passed to :class:`tfbus.BufferCore` / :class:`tfbus.Buffer`, whose results (tfbus
types, with the same field names) are returned as they are. See
``docs/moving-from-tf2-ros.md``.
"""

"""``tfbus view``: what a live 3D page shows of a tf tree (layer 5, a read-only consumer).

:mod:`tfbus.view.scene` is the pure model (no web library): given a
:class:`~tfbus.core.BufferCore`, a fixed frame, a time and when each frame was last
updated, it computes per frame its pose in the fixed frame (``lookup_transform``), its
parent, whether it is static, its fade state (rviz's TF display: full colour for the first
third of the frame timeout, fading to grey, then hidden) and tf2's message when it cannot
be placed. The web page itself (viser) lives in :mod:`tfbus.view.server`, imported only by
``tfbus view`` (the ``tfbus[view]`` extra).

Nothing below layer 5 imports this package.
"""

from __future__ import annotations

from tfbus.view.scene import (
    DEFAULT_FRAME_TIMEOUT,
    FrameView,
    Scene,
    build_scene,
    default_fixed_frame,
    fade,
)

__all__ = ["DEFAULT_FRAME_TIMEOUT", "FrameView", "Scene", "build_scene",
           "default_fixed_frame", "fade"]

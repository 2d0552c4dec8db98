"""``tfbus web``: tf for roslibjs and roslibpy web apps, from any tfbus bus, without ROS
or rosbridge (layer 5, a consumer like :mod:`tfbus.view`).

:class:`~tfbus.web.server.TfWebServer` speaks the rosbridge v2 JSON protocol
(rosbridge_suite ``ROSBRIDGE_PROTOCOL.md``) as far as tf goes
(:mod:`tfbus.web.rosbridge`): ``/tf`` and ``/tf_static`` subscribed and published,
tf2_web_republisher's ``TFSubscription`` goals (ROS 1 actionlib over topics, and the
ROS 2 action ops) and its ``republish_tfs`` service, which roslibjs's ``TFClient`` /
``ROS2TFClient`` and roslibpy's ``TFClient`` use, with each goal's fixed frame, source
frames, ``angular_thres``, ``trans_thres`` and ``rate`` applied server-side per client as
tf2_web_republisher does.
"""

from tfbus._extras import require

require(__name__, "wsproto")

from tfbus.web.rosbridge import Session, TfPair
from tfbus.web.server import TfWebServer

__all__ = ["Session", "TfPair", "TfWebServer"]

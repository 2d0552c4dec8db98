"""ROS 1 transport: tfbus takes part in a ROS 1 graph as a node (``/tf``, ``/tf_static``).

``Bus(transport=Ros1Transport())`` registers with a ROS 1 master as publisher and
subscriber of ``/tf`` and ``/tf_static`` (type ``tf2_msgs/TFMessage``, md5
``94810edda583a504dfda3829e70d7eec``) and exchanges messages with other nodes over TCPROS,
so the tutorial's C++ ``tf_broadcaster`` feeds a tfbus listener and a tfbus broadcaster
feeds the C++ ``tf_listener``, ``tf_echo``, ``tf_monitor`` or ``rostopic hz``.

What a node needs of ROS 1, and where it comes from (ROS wiki "ROS/Master_API",
"ROS/Slave_API", "ROS/TCPROS", "ROS/Connection Header"; ros_comm's ``rospy/impl``):

* master API (client): ``registerPublisher``, ``registerSubscriber``,
  ``unregisterPublisher``, ``unregisterSubscriber``, ``lookupNode``, over XML-RPC on
  anyio sockets (HTTP/1.0 by hand, bodies by :mod:`xmlrpc.client`), each call with one
  total deadline (``master_timeout``);
* slave API (server, on anyio sockets in the node's task group): ``requestTopic``,
  ``publisherUpdate``, ``getPid``, ``getBusInfo``, ``getBusStats``, ``getMasterUri``,
  ``getSubscriptions``, ``getPublications``, ``paramUpdate``, ``shutdown``;
* TCPROS: connection headers (``callerid``, ``topic``, ``md5sum``, ``type``,
  ``message_definition``, ``latching``, ``tcp_nodelay``), then length-prefixed messages.
  Messages are serialised by rosbags' ROS 1 serialiser (``Typestore.serialize_ros1``),
  which also yields the message definition and its md5; received ones are decoded by
  tfbus's struct decoder (:func:`tfbus.codecs.ros1.decode_tf`, tested equal to
  rosbags' ``deserialize_ros1``). On asyncio, frames are split, decoded and delivered in
  the event loop's read callback (an :class:`asyncio.BufferedProtocol`), as roscpp reads
  in its poll thread; on trio, in the connection's task.

Behaviour, as tf2_ros and roscpp do it:

* ``/tf_static`` is latched: every static transform this transport ever sent is kept,
  and each publish sends the full set in one message (tf2_ros's
  ``StaticTransformBroadcaster``), which a subscriber connecting later receives first;
* several publishers per topic; publishers that appear later (``publisherUpdate``); a
  dropped connection is retried while its publisher is still registered; a restarted
  master is noticed (``lookupNode`` every ``master_check_period``, 5 s) and this node
  registers again, without restarting tfbus;
* bad input costs one connection at most: a malformed header, an oversized or
  undecodable TCPROS frame closes that connection only and is counted in
  :meth:`Ros1Transport.statistics`; every other connection keeps delivering. XML-RPC
  from any peer (master, publisher, slave API client) is bounded: bodies to 1 MiB
  (:data:`~tfbus.transports.ros1.rpc.MAX_XMLRPC_BYTES`), nesting to 64 elements, each
  call to ``master_timeout`` in all and each served request to 5 s; an answer that is
  not ROS XML-RPC (or offers a port outside 1..65535) is counted in ``bad_replies`` and
  retried with back-off; a request refused is counted in ``bad_requests``. At most 16
  ``requestTopic`` calls run at once and 1024 publishers per topic are followed, so slow
  or numerous peers cannot starve a good one; an ``accept`` that fails (``EMFILE``: out
  of file descriptors) backs off and the listener goes on; a connection must send its
  header within ``max(master_timeout, 1)`` s. Leaving the bus takes at most ~1 s
  (unregistering, best effort) whatever peers do;
* other topics, of any ROS 1 type, carried as serialised bytes on the same node
  (:meth:`Ros1Transport.subscribe_raw`, :meth:`Ros1Transport.advertise_raw`,
  :meth:`Ros1Transport.send_raw_nowait`): tf2_ros's ``LookupTransform`` action, both
  ends (:mod:`~tfbus.transports.ros1.action`: :meth:`Ros1Transport.serve_lookups`,
  :meth:`Ros1Transport.lookup_client`, the ``LookupServing`` capability behind
  :class:`tfbus.remote.BufferServer` / :class:`tfbus.remote.BufferClient`, and
  :class:`tfbus.compat.tf2_ros.BufferClient`);
* ``/tf`` (or ``/tf_static``) is registered with the master when a broadcaster is made
  (:meth:`Ros1Transport.advertise`, as tf2_ros advertises at construction), so
  subscribers connect before the first message;
* loopback by default: the master defaults to ``http://127.0.0.1:11311`` and the node's
  own servers bind ``127.0.0.1``; while this node's host is a loopback address it
  connects to no publisher outside 127.0.0.0/8 (neither its XML-RPC URI, from the master
  or a ``publisherUpdate``, nor the TCPROS endpoint it offers; counted in
  ``refused_hosts``) (``allow_remote=True`` lifts that for a
  robot network). ``ROS_MASTER_URI``, ``ROS_IP`` and ``ROS_HOSTNAME`` are honoured as ROS
  does.

One module per concern, as every transport package (``docs/architecture.md``, "Adding a
transport"): :mod:`~tfbus.transports.ros1.transport` (:class:`Ros1Transport`, the node),
:mod:`~tfbus.transports.ros1.options` (the ``ros1`` bus spec),
:mod:`~tfbus.transports.ros1.rpc` (XML-RPC client and slave API server),
:mod:`~tfbus.transports.ros1.tcpros` (connection headers and frames),
:mod:`~tfbus.transports.ros1.action` (tf2_ros's ``LookupTransform`` action on the node's
raw topics: server and client); the message codec
is :mod:`tfbus.codecs.ros1`.
"""

from tfbus._extras import require

require(__name__, "rosbags", extra="ros1")

from tfbus.codecs.ros1 import TF_MD5SUM, TF_TYPE, TFCodec

from .tcpros import decode_header, encode_header
from .transport import Ros1Statistics, Ros1Transport

__all__ = [
    "TF_MD5SUM",
    "TF_TYPE",
    "Ros1Statistics",
    "Ros1Transport",
    "TFCodec",
    "decode_header",
    "encode_header",
]

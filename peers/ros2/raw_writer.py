"""A raw DDS writer on rt/tf in its own process, for tests/transports/test_ros2.py.

Run with the tfbus venv's python: ``raw_writer.py DOMAIN [clock]`` (``clock``: write
``rosgraph_msgs/msg/Clock`` samples on rt/clock with the ``/clock`` writer QoS instead).
Commands on stdin, one per line; one answer line each on stdout:

* ``W <hex>`` -- write these bytes as one serialized sample; answers ``RC <return code>``
  (0: written; negative: refused by Cyclone, which validates every sample).

It is a separate process because a DDS writer and a listening reader in one process can
deadlock (local delivery takes the reader's lock while holding the GIL; Cyclone's receive
thread holds that lock while waiting for the GIL). Loopback only: the Cyclone
configuration is tfbus's default one (127.0.0.1, no multicast).
"""

from __future__ import annotations

import sys

from cyclonedds import _clayer
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic

from tfbus.transports.ros2.dds import Clock_, TFMessage_, cyclone_config
from tfbus.transports.ros2.transport import CLOCK_WRITER_QOS, TF_WRITER_QOS


def main() -> None:
    domain_id = int(sys.argv[1])
    domain = Domain(domain_id, cyclone_config())
    participant = DomainParticipant(domain_id)
    if sys.argv[2:] == ["clock"]:
        topic = Topic(participant, "rt/clock", Clock_)
        writer = DataWriter(participant, topic, CLOCK_WRITER_QOS)
    else:
        writer = DataWriter(participant, Topic(participant, "rt/tf", TFMessage_), TF_WRITER_QOS)
    print("READY", flush=True)
    for line in sys.stdin:
        cmd, _, arg = line.strip().partition(" ")
        if cmd == "W":
            data = bytes.fromhex(arg)
            rc = _clayer.ddspy_write(writer._ref, data.ljust((len(data) + 3) & ~3, b"\0"))
            print(f"RC {int(rc)}", flush=True)
    # The test has received what it waited for before it closes stdin: nothing to flush.
    del writer, participant, domain


if __name__ == "__main__":
    main()

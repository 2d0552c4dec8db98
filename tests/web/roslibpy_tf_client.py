"""roslibpy's own ``TFClient`` (tf2_web_republisher's ``republish_tfs`` service, then its
``tf_repub_N`` topic) against ``tfbus web``: run in a subprocess by tests/web.

``python roslibpy_tf_client.py PORT FIXED_FRAME ANGULAR_THRES TRANS_THRES RATE FRAME...``
prints ``ready`` once connected, then one JSON line per transform received:
``{"frame": id, "translation": {...}, "rotation": {...}}``.
"""

import json
import sys

import roslibpy
from roslibpy.tf import TFClient

port, fixed, angular, trans, rate = sys.argv[1:6]
frames = sys.argv[6:]
ros = roslibpy.Ros("127.0.0.1", int(port))


def printer(frame):
    def show(transform):
        print(json.dumps({"frame": frame, **transform}), flush=True)
    return show


def start():
    print("ready", flush=True)
    client = TFClient(ros, fixed_frame=fixed, angular_threshold=float(angular),
                      translation_threshold=float(trans), rate=float(rate))
    for f in frames:
        client.subscribe(f, printer(f))


ros.on_ready(start, run_in_thread=False)
ros.run_forever()

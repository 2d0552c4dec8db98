// npm roslib's own TFClient (ROS 1: tf2_web_republisher's TFSubscription goal over
// actionlib topics) or ROS2TFClient (ROS 2: send_action_goal) against `tfbus web`; run by
// tests/web in Node with ROSLIB_DIR set by scripts/install/install_roslibjs.sh.
//   node roslibjs_tf_client.mjs URL ros1|ros2 FIXED_FRAME ANGULAR_THRES TRANS_THRES RATE FRAME...
// prints "ready" once connected, then one JSON line per transform received:
//   {"frame": id, "translation": {...}, "rotation": {...}}
import { pathToFileURL } from "node:url";
import { join } from "node:path";

const lib = await import(
  pathToFileURL(join(process.env.ROSLIB_DIR, "node_modules/roslib/dist/RosLib.js")).href
);
const [url, kind, fixedFrame, angular, trans, rate, ...frames] = process.argv.slice(2);
const ros = new lib.Ros({ url });
ros.on("error", (e) => console.error("error", String(e)));
ros.on("status", (m) => console.error("status", JSON.stringify(m)));
ros.on("connection", () => {
  console.log("ready");
  const Client = kind === "ros2" ? lib.ROS2TFClient : lib.TFClient;
  const client = new Client({
    ros,
    fixedFrame,
    angularThres: Number(angular),
    transThres: Number(trans),
    rate: Number(rate),
  });
  for (const frame of frames) {
    client.subscribe(frame, (tf) => {
      console.log(JSON.stringify({ frame, translation: tf.translation, rotation: tf.rotation }));
    });
  }
});

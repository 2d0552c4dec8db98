// npm roslib clients that subscribe to /tf on `tfbus web` and leave with a close handshake
// (`Ros.close()`, as a closing browser tab); run by tests/web in Node with ROSLIB_DIR set
// by scripts/install/install_roslibjs.sh.
//   node roslibjs_leaving_client.mjs URL N
// N connections each subscribe to /tf and close at their first message; prints "left N"
// once every connection reported its close, then exits.
import { pathToFileURL } from "node:url";
import { join } from "node:path";

const lib = await import(
  pathToFileURL(join(process.env.ROSLIB_DIR, "node_modules/roslib/dist/RosLib.js")).href
);
const [url, count] = process.argv.slice(2);
const n = Number(count);
let closed = 0;
const bound = setTimeout(() => { console.error("not every client left within 60 s"); process.exit(1); }, 60000);
for (let i = 0; i < n; i++) {
  const ros = new lib.Ros({ url });
  ros.on("error", (e) => console.error("error", String(e)));
  ros.on("close", () => {
    closed += 1;
    if (closed === n) {
      console.log(`left ${n}`);
      clearTimeout(bound);
      process.exit(0);
    }
  });
  ros.on("connection", () => {
    const topic = new lib.Topic({ ros, name: "/tf", messageType: "tf2_msgs/TFMessage" });
    let done = false;
    topic.subscribe(() => {
      if (!done) {
        done = true;
        ros.close(); // the close handshake, while /tf flows
      }
    });
  });
}

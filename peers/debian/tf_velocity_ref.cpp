// Reference answers from Debian's C++ libtf (ROS 1 tf 1.13): tf::Transformer::lookupTwist.
// Built and run by tests/core/test_velocity.py. Reads lines from stdin:
//   T parent child stamp_ns tx ty tz qx qy qz qw      store a transform
//   P parent child stamp_ns tx ty tz qx qy qz qw      store a static transform (tf2 buffer)
//   S tracking observation time_ns interval_ns        lookupTwist (4 arguments)
//   F tracking observation reference px py pz point_frame time_ns interval_ns
//                                                     lookupTwist (reference point form)
// and prints one line per query: "OK lx ly lz ax ay az" (%.17g) or "ERR <what>".
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>

#include <tf/tf.h>

int main() {
  tf::Transformer tr(true, ros::Duration(1000.0));
  std::string line;
  while (std::getline(std::cin, line)) {
    std::istringstream in(line);
    std::string kind;
    in >> kind;
    if (kind == "T" || kind == "P") {
      std::string parent, child;
      long long ns;
      double tx, ty, tz, qx, qy, qz, qw;
      in >> parent >> child >> ns >> tx >> ty >> tz >> qx >> qy >> qz >> qw;
      // Straight into tf2 as a message: a tf::Transform would keep a rotation matrix and
      // hand back a re-derived quaternion, not the numbers given.
      geometry_msgs::TransformStamped msg;
      msg.header.stamp.fromNSec(ns);
      msg.header.frame_id = parent;
      msg.child_frame_id = child;
      msg.transform.translation.x = tx;
      msg.transform.translation.y = ty;
      msg.transform.translation.z = tz;
      msg.transform.rotation.x = qx;
      msg.transform.rotation.y = qy;
      msg.transform.rotation.z = qz;
      msg.transform.rotation.w = qw;
      tr.getTF2BufferPtr()->setTransform(msg, "ref", kind == "P");
      continue;
    }
    geometry_msgs::Twist twist;
    try {
      if (kind == "S") {
        std::string tracking, observation;
        long long t, d;
        in >> tracking >> observation >> t >> d;
        ros::Time time;
        time.fromNSec(t);
        ros::Duration interval;
        interval.fromNSec(d);
        tr.lookupTwist(tracking, observation, time, interval, twist);
      } else if (kind == "F") {
        std::string tracking, observation, reference, point_frame;
        double px, py, pz;
        long long t, d;
        in >> tracking >> observation >> reference >> px >> py >> pz >> point_frame >> t >> d;
        ros::Time time;
        time.fromNSec(t);
        ros::Duration interval;
        interval.fromNSec(d);
        tr.lookupTwist(tracking, observation, reference, tf::Point(px, py, pz), point_frame, time,
                       interval, twist);
      } else {
        std::printf("ERR bad line\n");
        continue;
      }
    } catch (const tf::TransformException& e) {
      std::printf("ERR %s\n", e.what());
      std::fflush(stdout);
      continue;
    }
    std::printf("OK %.17g %.17g %.17g %.17g %.17g %.17g\n", twist.linear.x, twist.linear.y,
                twist.linear.z, twist.angular.x, twist.angular.y, twist.angular.z);
  }
  return 0;
}

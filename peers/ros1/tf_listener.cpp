// The listener of the ROS 1 tutorial "Setting up your robot using tf", written for tfbus's
// interop tests: node "robot_tf_listener" keeps a tf::TransformListener (10 s cache) and
// once a second transforms the point (1.0, 0.2, 0.0) of base_laser into base_link at the
// latest common time, logging the tutorial's line (its "0.20. 0.00" typo included, which
// the tests parse) or, when tf cannot answer, the tutorial's error line with tf's message.
#include <geometry_msgs/PointStamped.h>
#include <ros/ros.h>
#include <tf/transform_listener.h>

namespace {

void transform_point(const tf::TransformListener& listener) {
  geometry_msgs::PointStamped in_laser;
  in_laser.header.frame_id = "base_laser";
  in_laser.header.stamp = ros::Time();  // zero: the latest transform available
  in_laser.point.x = 1.0;
  in_laser.point.y = 0.2;
  in_laser.point.z = 0.0;
  try {
    geometry_msgs::PointStamped in_base;
    listener.transformPoint("base_link", in_laser, in_base);
    ROS_INFO("base_laser: (%.2f, %.2f. %.2f) -----> base_link: (%.2f, %.2f, %.2f) at time %.2f",
             in_laser.point.x, in_laser.point.y, in_laser.point.z, in_base.point.x,
             in_base.point.y, in_base.point.z, in_base.header.stamp.toSec());
  } catch (const tf::TransformException& ex) {
    ROS_ERROR("Received an exception trying to transform a point from \"base_laser\" to "
              "\"base_link\": %s", ex.what());
  }
}

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "robot_tf_listener");
  ros::NodeHandle node;
  tf::TransformListener listener(ros::Duration(10.0));
  ros::Timer timer = node.createTimer(
      ros::Duration(1.0), [&listener](const ros::TimerEvent&) { transform_point(listener); });
  ros::spin();
  return 0;
}

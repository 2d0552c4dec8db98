// The broadcaster of the ROS 1 tutorial "Setting up your robot using tf" (wiki.ros.org/
// navigation/Tutorials/RobotSetup/TF), written for tfbus's interop tests: node
// "robot_tf_publisher" sends base_link -> base_laser, translation (0.1, 0, 0.2), identity
// rotation, stamped now, 100 times a second on /tf until the node is shut down (SIGINT).
#include <ros/ros.h>
#include <tf/transform_broadcaster.h>

int main(int argc, char** argv) {
  ros::init(argc, argv, "robot_tf_publisher");
  ros::NodeHandle node;
  tf::TransformBroadcaster broadcaster;
  const tf::Transform laser_in_base(tf::Quaternion(0.0, 0.0, 0.0, 1.0),
                                    tf::Vector3(0.1, 0.0, 0.2));
  ros::Rate rate(100.0);
  while (node.ok()) {
    broadcaster.sendTransform(
        tf::StampedTransform(laser_in_base, ros::Time::now(), "base_link", "base_laser"));
    rate.sleep();
  }
  return 0;
}

// Benchmark publisher for benchmarks/bench_ros1.py: /tf at RATE Hz, FRAMES transforms per
// message (base_link -> bench_0 .. bench_{FRAMES-1}), each stamped ros::Time::now() just
// before publishing, for SECONDS; prints "sent <messages> <transforms>" at the end.
// The values are constant (bench_i at x = i, identity rotation), as a robot's fixed joints
// or one standing still; with a 4th argument "moving", every value changes in every
// message (x = i + 0.001 k, a rotation about z by 0.1 i + 0.001 k rad in message k), as a
// robot moving all its joints.
#include <ros/ros.h>
#include <tf2_msgs/TFMessage.h>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

int main(int argc, char** argv) {
  ros::init(argc, argv, "bench_pub");
  if (argc < 4) { std::fprintf(stderr, "usage: bench_pub RATE FRAMES SECONDS\n"); return 2; }
  const double rate = std::atof(argv[1]);
  const int frames = std::atoi(argv[2]);
  const double seconds = std::atof(argv[3]);
  const bool moving = argc > 4 && std::string(argv[4]) == "moving";
  ros::NodeHandle n;
  ros::Publisher pub = n.advertise<tf2_msgs::TFMessage>("tf", 1000);
  // Wait (bounded) until both subscribers (tfbus and bench_sub) are connected.
  for (int i = 0; i < 300 && ros::ok() && pub.getNumSubscribers() < 2; ++i) ros::Duration(0.05).sleep();
  ros::Duration(0.5).sleep();
  tf2_msgs::TFMessage msg;
  msg.transforms.resize(frames);
  for (int i = 0; i < frames; ++i) {
    msg.transforms[i].header.frame_id = "base_link";
    msg.transforms[i].child_frame_id = "bench_" + std::to_string(i);
    msg.transforms[i].transform.translation.x = i;
    msg.transforms[i].transform.rotation.w = 1.0;
  }
  ros::Rate r(rate);
  long sent = 0;
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(seconds);
  while (ros::ok() && ros::WallTime::now() < end) {
    const ros::Time now = ros::Time::now();
    for (auto& t : msg.transforms) t.header.stamp = now;
    if (moving) {
      for (int i = 0; i < frames; ++i) {
        const double a = 0.1 * i + 0.001 * sent;
        msg.transforms[i].transform.translation.x = i + 0.001 * sent;
        msg.transforms[i].transform.rotation.z = std::sin(a / 2);
        msg.transforms[i].transform.rotation.w = std::cos(a / 2);
      }
    }
    pub.publish(msg);
    ++sent;
    r.sleep();
  }
  ros::Duration(0.5).sleep();
  std::printf("sent %ld %ld\n", sent, sent * (long)frames);
  std::fflush(stdout);
  return 0;
}

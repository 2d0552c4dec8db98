// Benchmark subscriber for benchmarks/bench_ros1.py: records, per /tf message, the latency
// ros::Time::now() - header.stamp of its first transform, in microseconds; on SIGINT prints
// "received <messages> <transforms>" and one latency per line after "latencies".
#include <ros/ros.h>
#include <tf2_msgs/TFMessage.h>
#include <cstdio>
#include <vector>

static std::vector<double> lat;
static long msgs = 0, tfs = 0;

void cb(const tf2_msgs::TFMessage::ConstPtr& m) {
  const ros::Time now = ros::Time::now();
  ++msgs;
  tfs += m->transforms.size();
  if (!m->transforms.empty()) lat.push_back((now - m->transforms[0].header.stamp).toSec() * 1e6);
}

int main(int argc, char** argv) {
  ros::init(argc, argv, "bench_sub");
  ros::NodeHandle n;
  ros::Subscriber s = n.subscribe("tf", 1000, cb, ros::TransportHints().tcpNoDelay());
  std::printf("READY\n");
  std::fflush(stdout);
  ros::spin();
  std::printf("received %ld %ld\nlatencies\n", msgs, tfs);
  for (double v : lat) std::printf("%.3f\n", v);
  std::fflush(stdout);
  return 0;
}

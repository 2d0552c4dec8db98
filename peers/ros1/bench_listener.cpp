// Listener benchmark peer for benchmarks/bench_ros1.py (--mode listener): a
// tf2_ros::TransformListener feeding a tf2_ros::Buffer, as a ROS 1 user writes it. The
// buffer's transforms-changed signal (BufferCore::_addTransformsChangedListener) fires
// after each setTransform; after the FRAMES-th of a message (the whole message is in the
// buffer) it records ros::Time::now() - the stamp of base_link -> bench_0 now in the
// buffer, in microseconds. On SIGINT prints "received <messages> <transforms>" and one
// latency per line after "latencies", like bench_sub.
#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>
#include <cstdio>
#include <cstdlib>
#include <vector>

static std::vector<double> lat;
static long changes = 0;
static long frames = 1;
static tf2_ros::Buffer* buffer = nullptr;

void changed() {
  const ros::Time now = ros::Time::now();
  if (++changes % frames != 0) return;
  try {
    const ros::Time stamp = buffer->lookupTransform("base_link", "bench_0", ros::Time(0)).header.stamp;
    lat.push_back((now - stamp).toSec() * 1e6);
  } catch (const tf2::TransformException&) {
  }
}

int main(int argc, char** argv) {
  ros::init(argc, argv, "bench_listener");
  if (argc < 2) { std::fprintf(stderr, "usage: bench_listener FRAMES\n"); return 2; }
  frames = std::atol(argv[1]);
  if (frames < 1) frames = 1;
  ros::NodeHandle n;
  tf2_ros::Buffer buf;
  buffer = &buf;
  buf._addTransformsChangedListener(changed);
  tf2_ros::TransformListener listener(buf);  // its own spin thread, as by default
  std::printf("READY\n");
  std::fflush(stdout);
  ros::spin();
  std::printf("received %ld %ld\nlatencies\n", changes / frames, changes);
  for (double v : lat) std::printf("%.3f\n", v);
  std::fflush(stdout);
  return 0;
}

// The C++ half of benchmarks/bench_sensors.py: ROS 1 laser_geometry with a tf2::BufferCore,
// the same scenario as the Python half. Reads "<beams> <reps>" on stdin, prints
// "project_ns <ns per projectLaser> transform_ns <ns per transformLaserScanToPointCloud>",
// CPU time of this (single-threaded) process, so a loaded machine does not inflate it.
// Build: g++ -O2 -o bench laser_geometry_bench.cpp $(pkg-config --cflags --libs laser_geometry)
#include <laser_geometry/laser_geometry.h>
#include <tf2/buffer_core.h>

#include <time.h>

#include <cmath>
#include <iostream>

static double cpu_ns() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e9 + ts.tv_nsec;
}

int main() {
  int beams = 720, reps = 2000;
  std::cin >> beams >> reps;
  tf2::BufferCore core(ros::Duration(100.0));
  // odom -> base_link: a 2 m circle at 1 rad/s, 50 Hz for 10 s; base_link -> base_laser static.
  for (int j = 0; j <= 500; ++j) {
    double t = j * 0.02, yaw = t + M_PI / 2;
    geometry_msgs::TransformStamped ts;
    ts.header.frame_id = "odom";
    ts.child_frame_id = "base_link";
    ts.header.stamp = ros::Time(1000, 0) + ros::Duration(t);
    ts.transform.translation.x = 2 * std::cos(t);
    ts.transform.translation.y = 2 * std::sin(t);
    ts.transform.rotation.z = std::sin(yaw / 2);
    ts.transform.rotation.w = std::cos(yaw / 2);
    core.setTransform(ts, "bench");
  }
  geometry_msgs::TransformStamped st;
  st.header.frame_id = "base_link";
  st.child_frame_id = "base_laser";
  st.transform.translation.x = 0.1;
  st.transform.translation.z = 0.2;
  st.transform.rotation.w = 1.0;
  core.setTransform(st, "bench", true);
  sensor_msgs::LaserScan scan;
  scan.header.frame_id = "base_laser";
  scan.header.stamp = ros::Time(1005, 10000000);
  scan.angle_min = -M_PI;
  scan.angle_increment = 2 * M_PI / beams;
  scan.angle_max = scan.angle_min + (beams - 1) * scan.angle_increment;
  scan.time_increment = 1.0 / 40 / beams;
  scan.range_min = 0.05;
  scan.range_max = 30.0;
  scan.ranges.resize(beams);
  scan.intensities.resize(beams);
  for (int i = 0; i < beams; ++i) {
    scan.ranges[i] = 1.0 + 0.01 * (i % 300);
    scan.intensities[i] = i;
  }
  laser_geometry::LaserProjection projector;
  sensor_msgs::PointCloud2 cloud;
  double best_p = 1e30, best_t = 1e30;
  for (int round = 0; round < 5; ++round) {
    double t0 = cpu_ns();
    for (int k = 0; k < reps; ++k) projector.projectLaser(scan, cloud);
    double t1 = cpu_ns();
    for (int k = 0; k < reps; ++k)
      projector.transformLaserScanToPointCloud("odom", scan, cloud, core);
    double t2 = cpu_ns();
    best_p = std::min(best_p, (t1 - t0) / reps);
    best_t = std::min(best_t, (t2 - t1) / reps);
  }
  std::cout << "project_ns " << best_p << " transform_ns " << best_t << " width " << cloud.width
            << "\n";
  return 0;
}

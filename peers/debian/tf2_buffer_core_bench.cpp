// The C++ reference of the core rows (bench_check.py, bench_core.py): Debian's tf2
// (ROS 1 geometry2 0.7.6) tf2::BufferCore called from C++, the same scenarios as tfbus's side
// (tf2_cpp.py hands them over on stdin and parses the one JSON line printed on stdout).
// Build: g++ -O2 -o tf2_buffer_core_bench tf2_buffer_core_bench.cpp $(pkg-config --cflags --libs tf2)
//
// stdin, whitespace separated integers:
//   cache_time_ns period_ns t0_ns chain_stamps
//   n_depths depth...                              lookup chains f0 <- f1 <- ... <- f<depth>
//   calls repeats query_ns... recent_ns...         2 x calls * repeats never-repeated times:
//                                                  spread over the whole history, then within
//                                                  its newest 100 ms (what robots ask for)
//   fill_links fill_samples fill_buffers           a fresh buffer's first samples, star root <- c<i>
//   steady_links steady_warm steady_samples        the same after steady_warm samples per link
//   mem_frames mem_samples                         memory per sample (RSS growth), frame by frame
// stdout, one JSON object, CPU seconds per call (this thread's, best run) and bytes per sample:
//   {"lookup_s": {"<depth>/interp": s, "<depth>/recent": s, ...}, "fill_s": s, "steady_s": s, "rss_bytes_per_sample": b}
#include <tf2/buffer_core.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include <time.h>

namespace {

const int64_t NS = 1000000000;

ros::Time ros_time(int64_t ns) { return ros::Time(ns / NS, ns % NS); }

// The values of benchmarks/bench_core.py _transform(k).
geometry_msgs::TransformStamped message(const std::string& parent, const std::string& child,
                                        int64_t stamp_ns, int k) {
  geometry_msgs::TransformStamped m;
  m.header.frame_id = parent;
  m.child_frame_id = child;
  m.header.stamp = ros_time(stamp_ns);
  double s = 0.01 * (k % 11);
  m.transform.translation.x = 1.0 + 0.001 * (k % 7);
  m.transform.translation.y = 0.5;
  m.transform.translation.z = -0.25;
  m.transform.rotation.x = s;
  m.transform.rotation.w = std::sqrt(1.0 - s * s);
  return m;
}

// This thread's CPU time, s: what the Python side measures too (time.thread_time), so that
// other work on a shared machine, which preempts either side, does not enter the ratios.
double now() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

int64_t rss_bytes() {
  long pages = 0, resident = 0;
  FILE* f = std::fopen("/proc/self/statm", "r");
  if (f == nullptr) return 0;
  if (std::fscanf(f, "%ld %ld", &pages, &resident) != 2) resident = 0;
  std::fclose(f);
  return static_cast<int64_t>(resident) * 4096;
}

std::string name(const char* prefix, int i) { return prefix + std::to_string(i); }

}  // namespace

int main() {
  int64_t cache_ns, period, t0, n_stamps;
  std::cin >> cache_ns >> period >> t0 >> n_stamps;
  int n_depths;
  std::cin >> n_depths;
  std::vector<int> depths(n_depths);
  for (int& d : depths) std::cin >> d;
  int calls, repeats;
  std::cin >> calls >> repeats;
  std::vector<ros::Time> queries(static_cast<size_t>(calls) * repeats);
  std::vector<ros::Time> recent(queries.size());
  for (std::vector<ros::Time>* set : {&queries, &recent})
    for (ros::Time& q : *set) {
      int64_t ns;
      std::cin >> ns;
      q = ros_time(ns);
    }
  int fill_links, fill_samples, fill_buffers, steady_links, steady_warm, steady_samples;
  int mem_frames, mem_samples;
  std::cin >> fill_links >> fill_samples >> fill_buffers >> steady_links >> steady_warm >>
      steady_samples >> mem_frames >> mem_samples;
  if (!std::cin) {
    std::cerr << "bad scenario on stdin\n";
    return 2;
  }
  const ros::Duration cache_time(static_cast<double>(cache_ns) / NS);
  const std::string authority = "bench";

  // Memory first, in a fresh process: RSS growth of a buffer of mem_frames x mem_samples.
  double rss_per_sample;
  {
    tf2::BufferCore core(cache_time);
    geometry_msgs::TransformStamped m = message("root", "c0", t0, 3);
    int64_t before = rss_bytes();
    for (int f = 0; f < mem_frames; ++f) {
      m.child_frame_id = name("c", f);
      for (int k = 0; k < mem_samples; ++k) {
        m.header.stamp = ros_time(t0 + k * period);
        core.setTransform(m, authority);
      }
    }
    rss_per_sample = static_cast<double>(rss_bytes() - before) / (mem_frames * mem_samples);
  }

  // Lookups on chains, at interpolated times never repeated.
  std::cout.precision(17);
  std::cout << "{\"lookup_s\": {";
  for (size_t di = 0; di < depths.size(); ++di) {
    int depth = depths[di];
    tf2::BufferCore core(cache_time);
    for (int64_t k = 0; k < n_stamps; ++k)
      for (int i = 0; i < depth; ++i)
        core.setTransform(message(name("f", i), name("f", i + 1), t0 + k * period, k + i),
                          authority);
    const std::string root = "f0", leaf = name("f", depth);
    for (const char* label : {"interp", "recent"}) {
      const std::vector<ros::Time>& times = label[0] == 'i' ? queries : recent;
      double best = 1e30, sink = 0;
      for (int r = 0; r < repeats; ++r) {
        double start = now();
        for (int c = 0; c < calls; ++c)
          sink += core.lookupTransform(root, leaf, times[r * calls + c]).transform.translation.x;
        best = std::min(best, (now() - start) / calls);
      }
      if (sink == 12345.678) std::cerr << sink;  // keep the results alive
      std::cout << (di || label[0] == 'r' ? ", " : "") << "\"" << depth << "/" << label
                << "\": " << best;
    }
  }
  std::cout << "}";

  // set_transform by phase: a link's first fill_samples samples in a fresh buffer, and the
  // steady state (a full cache, pruning on every insert). A star root <- c<i>, stamps in
  // order, every link at each stamp in turn (a robot's tree at 100 Hz).
  std::vector<geometry_msgs::TransformStamped> fill;
  for (int k = 0; k < fill_samples; ++k)
    for (int i = 0; i < fill_links; ++i)
      fill.push_back(message("root", name("c", i), t0 + k * period, k + i));
  double best_fill = 1e30;
  for (int b = 0; b < fill_buffers; ++b) {
    tf2::BufferCore core(cache_time);
    double start = now();
    for (const auto& m : fill) core.setTransform(m, authority);
    best_fill = std::min(best_fill, (now() - start) / fill.size());
  }
  std::vector<geometry_msgs::TransformStamped> steady;
  for (int k = steady_warm; k < steady_warm + steady_samples; ++k)
    for (int i = 0; i < steady_links; ++i)
      steady.push_back(message("root", name("c", i), t0 + k * period, k + i));
  double best_steady = 1e30;
  for (int r = 0; r < repeats; ++r) {
    tf2::BufferCore core(cache_time);
    for (int k = 0; k < steady_warm; ++k)
      for (int i = 0; i < steady_links; ++i)
        core.setTransform(message("root", name("c", i), t0 + k * period, k + i), authority);
    double start = now();
    for (const auto& m : steady) core.setTransform(m, authority);
    best_steady = std::min(best_steady, (now() - start) / steady.size());
  }
  std::cout << ", \"fill_s\": " << best_fill << ", \"steady_s\": " << best_steady
            << ", \"rss_bytes_per_sample\": " << rss_per_sample << "}" << std::endl;
  return 0;
}

// The C++ reference of the core rows (bench_check.py, bench_core.py): Debian's tf2
// (ROS 1 geometry2 0.7.6) tf2::BufferCore called from C++, the same scenarios as tfbus's side
// (bench_core.py hands them over on stdin and parses the one JSON line printed on stdout).
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
//
// With --serve: the same scenario on stdin, then "READY" on stdout, then one measurement per
// command read from stdin, its CPU seconds per call on a line of its own (flushed), until
// "quit" or the end of stdin; no memory figure. Commands:
//   fill                  one fresh buffer's first fill_samples samples per link
//   steady                one buffer warmed with steady_warm samples per link, then timed
//   lookup D L R          the depth D chain (D one of the depths), L interp or recent, the
//                         calls of repeat R (0 <= R < repeats)
// bench_check.py alternates them with tfbus's same measurement a pair at a time, so that
// both sides of a pair run within milliseconds of each other, at the same machine speed.
#include <tf2/buffer_core.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <map>
#include <memory>
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

struct Scenario {
  int64_t cache_ns = 0, period = 0, t0 = 0, n_stamps = 0;
  std::vector<int> depths;
  int calls = 0, repeats = 0;
  std::vector<ros::Time> queries, recent;
  int fill_links = 0, fill_samples = 0, fill_buffers = 0;
  int steady_links = 0, steady_warm = 0, steady_samples = 0;
  int mem_frames = 0, mem_samples = 0;
};

bool read_scenario(Scenario& sc) {
  std::cin >> sc.cache_ns >> sc.period >> sc.t0 >> sc.n_stamps;
  int n_depths = 0;
  std::cin >> n_depths;
  if (!std::cin || n_depths < 0 || n_depths > 1000) return false;
  sc.depths.resize(n_depths);
  for (int& d : sc.depths) std::cin >> d;
  std::cin >> sc.calls >> sc.repeats;
  if (!std::cin || sc.calls <= 0 || sc.repeats <= 0) return false;
  sc.queries.resize(static_cast<size_t>(sc.calls) * sc.repeats);
  sc.recent.resize(sc.queries.size());
  for (std::vector<ros::Time>* set : {&sc.queries, &sc.recent})
    for (ros::Time& q : *set) {
      int64_t ns;
      std::cin >> ns;
      q = ros_time(ns);
    }
  std::cin >> sc.fill_links >> sc.fill_samples >> sc.fill_buffers >> sc.steady_links >>
      sc.steady_warm >> sc.steady_samples >> sc.mem_frames >> sc.mem_samples;
  return static_cast<bool>(std::cin);
}

const std::string AUTHORITY = "bench";

// The chain f0 <- f1 <- ... <- f<depth>, n_stamps samples per link.
std::unique_ptr<tf2::BufferCore> chain(const Scenario& sc, const ros::Duration& cache_time,
                                       int depth) {
  std::unique_ptr<tf2::BufferCore> core(new tf2::BufferCore(cache_time));
  for (int64_t k = 0; k < sc.n_stamps; ++k)
    for (int i = 0; i < depth; ++i)
      core->setTransform(message(name("f", i), name("f", i + 1), sc.t0 + k * sc.period, k + i),
                         AUTHORITY);
  return core;
}

// CPU seconds per call of one repeat's lookups from f0 to the leaf.
double lookup_once(tf2::BufferCore& core, int depth, const std::vector<ros::Time>& times,
                   int calls, int r) {
  const std::string root = "f0", leaf = name("f", depth);
  double sink = 0;
  double start = now();
  for (int c = 0; c < calls; ++c)
    sink += core.lookupTransform(root, leaf, times[r * calls + c]).transform.translation.x;
  double per_call = (now() - start) / calls;
  if (sink == 12345.678) std::cerr << sink;  // keep the results alive
  return per_call;
}

// set_transform by phase: a link's first fill_samples samples in a fresh buffer, and the
// steady state (a full cache, pruning on every insert). A star root <- c<i>, stamps in
// order, every link at each stamp in turn (a robot's tree at 100 Hz).
std::vector<geometry_msgs::TransformStamped> star(const Scenario& sc, int links, int first,
                                                  int count) {
  std::vector<geometry_msgs::TransformStamped> out;
  for (int k = first; k < first + count; ++k)
    for (int i = 0; i < links; ++i)
      out.push_back(message("root", name("c", i), sc.t0 + k * sc.period, k + i));
  return out;
}

double fill_once(const ros::Duration& cache_time,
                 const std::vector<geometry_msgs::TransformStamped>& fill) {
  tf2::BufferCore core(cache_time);
  double start = now();
  for (const auto& m : fill) core.setTransform(m, AUTHORITY);
  return (now() - start) / fill.size();
}

double steady_once(const ros::Duration& cache_time,
                   const std::vector<geometry_msgs::TransformStamped>& warm,
                   const std::vector<geometry_msgs::TransformStamped>& steady) {
  tf2::BufferCore core(cache_time);
  for (const auto& m : warm) core.setTransform(m, AUTHORITY);  // untimed
  double start = now();
  for (const auto& m : steady) core.setTransform(m, AUTHORITY);
  return (now() - start) / steady.size();
}

// --serve: one measurement per command (see the head of this file).
int serve(const Scenario& sc, const ros::Duration& cache_time) {
  std::map<int, std::unique_ptr<tf2::BufferCore>> chains;
  for (int depth : sc.depths) chains[depth] = chain(sc, cache_time, depth);
  const auto fill = star(sc, sc.fill_links, 0, sc.fill_samples);
  const auto warm = star(sc, sc.steady_links, 0, sc.steady_warm);
  const auto steady = star(sc, sc.steady_links, sc.steady_warm, sc.steady_samples);
  std::cout.precision(17);
  std::cout << "READY" << std::endl;
  std::string command;
  while (std::cin >> command && command != "quit") {
    double s;
    if (command == "fill") {
      s = fill_once(cache_time, fill);
    } else if (command == "steady") {
      s = steady_once(cache_time, warm, steady);
    } else if (command == "lookup") {
      int depth = -1, r = -1;
      std::string label;
      std::cin >> depth >> label >> r;
      auto found = chains.find(depth);
      if (!std::cin || found == chains.end() || (label != "interp" && label != "recent") ||
          r < 0 || r >= sc.repeats) {
        std::cerr << "bad lookup command\n";
        return 2;
      }
      s = lookup_once(*found->second, depth, label == "interp" ? sc.queries : sc.recent,
                      sc.calls, r);
    } else {
      std::cerr << "unknown command: " << command << "\n";
      return 2;
    }
    std::cout << s << std::endl;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Scenario sc;
  if (!read_scenario(sc)) {
    std::cerr << "bad scenario on stdin\n";
    return 2;
  }
  const ros::Duration cache_time(static_cast<double>(sc.cache_ns) / NS);
  if (argc > 1 && std::string(argv[1]) == "--serve") return serve(sc, cache_time);

  // Memory first, in a fresh process: RSS growth of a buffer of mem_frames x mem_samples.
  double rss_per_sample;
  {
    tf2::BufferCore core(cache_time);
    geometry_msgs::TransformStamped m = message("root", "c0", sc.t0, 3);
    int64_t before = rss_bytes();
    for (int f = 0; f < sc.mem_frames; ++f) {
      m.child_frame_id = name("c", f);
      for (int k = 0; k < sc.mem_samples; ++k) {
        m.header.stamp = ros_time(sc.t0 + k * sc.period);
        core.setTransform(m, AUTHORITY);
      }
    }
    rss_per_sample = static_cast<double>(rss_bytes() - before) / (sc.mem_frames * sc.mem_samples);
  }

  // Lookups on chains, at interpolated times never repeated.
  std::cout.precision(17);
  std::cout << "{\"lookup_s\": {";
  for (size_t di = 0; di < sc.depths.size(); ++di) {
    int depth = sc.depths[di];
    auto core = chain(sc, cache_time, depth);
    for (const char* label : {"interp", "recent"}) {
      const std::vector<ros::Time>& times = label[0] == 'i' ? sc.queries : sc.recent;
      double best = 1e30;
      for (int r = 0; r < sc.repeats; ++r)
        best = std::min(best, lookup_once(*core, depth, times, sc.calls, r));
      std::cout << (di || label[0] == 'r' ? ", " : "") << "\"" << depth << "/" << label
                << "\": " << best;
    }
  }
  std::cout << "}";

  const auto fill = star(sc, sc.fill_links, 0, sc.fill_samples);
  double best_fill = 1e30;
  for (int b = 0; b < sc.fill_buffers; ++b)
    best_fill = std::min(best_fill, fill_once(cache_time, fill));
  const auto warm = star(sc, sc.steady_links, 0, sc.steady_warm);
  const auto steady = star(sc, sc.steady_links, sc.steady_warm, sc.steady_samples);
  double best_steady = 1e30;
  for (int r = 0; r < sc.repeats; ++r)
    best_steady = std::min(best_steady, steady_once(cache_time, warm, steady));
  std::cout << ", \"fill_s\": " << best_fill << ", \"steady_s\": " << best_steady
            << ", \"rss_bytes_per_sample\": " << rss_per_sample << "}" << std::endl;
  return 0;
}

// Reference side of tests/sensors/test_laser.py: ROS 1 laser_geometry (Debian liblaser-geometry-dev)
// with a tf2::BufferCore, driven by a line-based text file on stdin.
//
// Input lines (whitespace-separated tokens; doubles as C99 hex floats, "inf", "nan"):
//   TF <static 0|1> <sec> <nsec> <parent> <child> <tx> <ty> <tz> <qx> <qy> <qz> <qw>
//   SCAN <id> <frame> <sec> <nsec> <angle_min> <angle_max> <angle_increment>
//        <time_increment> <scan_time> <range_min> <range_max> <n> <ranges...> <m> <intensities...>
//   DO <case id> <scan id> <P|T|F> <target|-> <fixed|-> <range_cutoff> <channel_options>
//      P: projectLaser; T: transformLaserScanToPointCloud(target, scan, cloud, tf);
//      F: the fixed-frame overload. One LaserProjection serves every DO, as in a node.
// Output, one line per DO:
//   OK <id> <width> <point_step> <name:offset:datatype,...> <data as hex bytes>
//   ERR <id> <exception class> <what() with \ and newlines escaped>
// Build: g++ -O2 -o harness laser_geometry_ref.cpp $(pkg-config --cflags --libs laser_geometry)
#include <laser_geometry/laser_geometry.h>
#include <tf2/buffer_core.h>
#include <tf2/exceptions.h>

#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <map>
#include <sstream>
#include <string>

static double num(std::istream &in) {
  std::string tok;
  in >> tok;
  return std::strtod(tok.c_str(), nullptr);
}

static std::string escape(const std::string &s) {
  std::string out;
  for (char c : s) {
    if (c == '\\') out += "\\\\";
    else if (c == '\n') out += "\\n";
    else out += c;
  }
  return out;
}

int main() {
  std::ios::sync_with_stdio(false);
  tf2::BufferCore core(ros::Duration(100000.0));
  laser_geometry::LaserProjection projector;
  std::map<std::string, sensor_msgs::LaserScan> scans;
  std::string line;
  while (std::getline(std::cin, line)) {
    std::istringstream in(line);
    std::string kind;
    in >> kind;
    if (kind == "TF") {
      int is_static;
      long sec, nsec;
      geometry_msgs::TransformStamped ts;
      in >> is_static >> sec >> nsec >> ts.header.frame_id >> ts.child_frame_id;
      ts.header.stamp = ros::Time(sec, nsec);
      ts.transform.translation.x = num(in);
      ts.transform.translation.y = num(in);
      ts.transform.translation.z = num(in);
      ts.transform.rotation.x = num(in);
      ts.transform.rotation.y = num(in);
      ts.transform.rotation.z = num(in);
      ts.transform.rotation.w = num(in);
      core.setTransform(ts, "harness", is_static != 0);
    } else if (kind == "SCAN") {
      std::string id;
      long sec, nsec;
      sensor_msgs::LaserScan scan;
      in >> id >> scan.header.frame_id >> sec >> nsec;
      scan.header.stamp = ros::Time(sec, nsec);
      scan.angle_min = num(in);
      scan.angle_max = num(in);
      scan.angle_increment = num(in);
      scan.time_increment = num(in);
      scan.scan_time = num(in);
      scan.range_min = num(in);
      scan.range_max = num(in);
      size_t n, m;
      in >> n;
      scan.ranges.resize(n);
      for (size_t i = 0; i < n; ++i) scan.ranges[i] = num(in);
      in >> m;
      scan.intensities.resize(m);
      for (size_t i = 0; i < m; ++i) scan.intensities[i] = num(in);
      scans[id] = scan;
    } else if (kind == "DO") {
      std::string id, scan_id, mode, target, fixed;
      in >> id >> scan_id >> mode >> target >> fixed;
      double cutoff = num(in);
      int options;
      in >> options;
      const sensor_msgs::LaserScan &scan = scans.at(scan_id);
      sensor_msgs::PointCloud2 cloud;
      try {
        if (mode == "P")
          projector.projectLaser(scan, cloud, cutoff, options);
        else if (mode == "T")
          projector.transformLaserScanToPointCloud(target, scan, cloud, core, cutoff, options);
        else
          projector.transformLaserScanToPointCloud(target, scan, cloud, fixed, core, cutoff,
                                                   options);
      } catch (tf2::LookupException &e) {
        std::cout << "ERR " << id << " LookupException " << escape(e.what()) << "\n";
        continue;
      } catch (tf2::ConnectivityException &e) {
        std::cout << "ERR " << id << " ConnectivityException " << escape(e.what()) << "\n";
        continue;
      } catch (tf2::ExtrapolationException &e) {
        std::cout << "ERR " << id << " ExtrapolationException " << escape(e.what()) << "\n";
        continue;
      } catch (tf2::InvalidArgumentException &e) {
        std::cout << "ERR " << id << " InvalidArgumentException " << escape(e.what()) << "\n";
        continue;
      } catch (std::exception &e) {
        std::cout << "ERR " << id << " Error " << escape(e.what()) << "\n";
        continue;
      }
      std::cout << "OK " << id << " " << cloud.width << " " << cloud.point_step << " ";
      for (size_t k = 0; k < cloud.fields.size(); ++k) {
        const sensor_msgs::PointField &f = cloud.fields[k];
        std::cout << (k ? "," : "") << f.name << ":" << f.offset << ":" << int(f.datatype);
      }
      if (cloud.fields.empty()) std::cout << "-";
      std::cout << " ";
      static const char *hex = "0123456789abcdef";
      std::string data;
      data.reserve(cloud.data.size() * 2 + 1);
      for (unsigned char b : cloud.data) {
        data += hex[b >> 4];
        data += hex[b & 15];
      }
      std::cout << (data.empty() ? "-" : data) << "\n";
    }
  }
  return 0;
}

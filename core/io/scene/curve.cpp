#include "core/io/scene/shapes.h"

#include <fstream>
#include <sstream>

// B-spline fibre curves ("bsplinecurve", Mitsuba's type): "filename", a text file with one control
// point "x y z r" per line and a blank line between curves ('#' starts a comment), or arrays
// "control_points" (N x 4) with "curve_offsets" (the first control point of each curve; one curve
// when absent). to_world must be a similarity; it scales the radii.
namespace limn::io_detail {

namespace {

void read_curve_file(const Props& p, const std::string& path, std::vector<float>& cps, std::vector<uint32_t>& offsets) {
  std::ifstream in(path);
  if (!in) p.fail("cannot read curve file '" + path + "'");
  std::string line;
  size_t line_no = 0;
  bool in_curve = false;
  while (std::getline(in, line)) {
    ++line_no;
    const size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream s(line);
    std::vector<double> v;
    std::string tok;
    while (s >> tok) {
      try {
        size_t used = 0;
        v.push_back(std::stod(tok, &used));
        if (used != tok.size()) throw std::invalid_argument(tok);
      } catch (const std::exception&) {
        p.fail("curve file '" + path + "', line " + std::to_string(line_no) + ": '" + tok + "' is not a number");
      }
    }
    if (v.empty()) {  // a blank line ends the current curve
      in_curve = false;
      continue;
    }
    if (v.size() != 4)
      p.fail("curve file '" + path + "', line " + std::to_string(line_no) + ": expected 4 numbers 'x y z r' (got " + std::to_string(v.size()) + ")");
    if (!in_curve) offsets.push_back(uint32_t(cps.size() / 4));
    in_curve = true;
    for (double x : v) cps.push_back(float(x));
  }
  if (cps.empty()) p.fail("curve file '" + path + "' holds no control points");
}

}  // namespace

ShapeGeometry load_bsplinecurve(const Props& p, const std::string&, const Transform& to_world) {
  BSplineCurve c;
  std::vector<uint32_t> offsets;
  if (p.has("filename") == p.has("control_points"))
    p.fail("needs exactly one of 'filename' (a text file of 'x y z r' lines) or 'control_points' (an N x 4 array)");
  if (p.has("filename")) {
    const std::string path = p.file("filename");
    c.source = "file '" + path + "'";
    read_curve_file(p, path, c.control_points, offsets);
    if (p.has("curve_offsets")) p.fail("'curve_offsets' goes with 'control_points'; the file separates curves by blank lines");
  } else {
    c.source = "'control_points'";
    const ArrayData a = p.array("control_points");
    if (a.shape.size() != 2 || a.shape[1] != 4) p.fail("'control_points' must have shape (N, 4): x, y, z, radius");
    c.control_points.assign(a.values.begin(), a.values.end());
    const size_t n = a.shape[0];
    if (p.has("curve_offsets")) {
      const ArrayData o = p.array("curve_offsets");
      if (o.shape.size() != 1 || o.values.empty()) p.fail("'curve_offsets' must be a 1D array of the first control point of each curve");
      for (size_t i = 0; i < o.values.size(); ++i) {
        const double x = o.values[i];
        if (!(x >= 0 && x < double(n) && x == std::floor(x)))
          p.fail("'curve_offsets' entry " + std::to_string(i) + " (" + std::to_string(x) + ") is not a control point index below " + std::to_string(n));
        if (i == 0 && x != 0) p.fail("'curve_offsets' must start at 0 (got " + std::to_string(x) + ")");
        if (i > 0 && !(x > o.values[i - 1])) p.fail("'curve_offsets' must increase (entry " + std::to_string(i) + ")");
        offsets.push_back(uint32_t(x));
      }
    } else {
      offsets.push_back(0);
    }
  }
  offsets.push_back(uint32_t(c.control_points.size() / 4));
  c.curve_offsets = offsets;
  if (p.has("to_world")) {
    const float scale = float(check_similarity(p, to_world));
    for (size_t i = 0; i < c.point_count(); ++i) {
      const Vec3 q = to_world.point(c.point(i));
      c.control_points[4 * i] = q.x, c.control_points[4 * i + 1] = q.y, c.control_points[4 * i + 2] = q.z;
      c.control_points[4 * i + 3] *= scale;
    }
  }
  const std::string problem = c.check(c.control_points.data());
  if (!problem.empty()) p.fail(c.source + ": " + problem);
  return c;
}

}  // namespace limn::io_detail

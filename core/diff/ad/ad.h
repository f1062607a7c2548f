// Reverse-mode automatic differentiation for one light path at a time.
//
// A Var is a double value plus the index of its node on a thread-local Tape; each node keeps up to
// two parents with their local partials. One path is replayed on the tape, the tape is swept once
// backwards from the path's contribution, and the adjoints of the input nodes are scattered into
// parameter gradients; then the tape is cleared. Memory is bounded by the longest path, not by the
// image. Values are doubles so that derivatives of normalisations and differences of nearby points
// keep their precision; the primal renderer stays in float.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace limn::ad {

struct Node {
  int32_t a, b;     // parents (-1: none)
  double da, db;    // d(node)/d(parent)
};

class Tape {
 public:
  int32_t push(int32_t a, double da, int32_t b = -1, double db = 0.0) {
    m_nodes.push_back({a, b, da, db});
    return int32_t(m_nodes.size() - 1);
  }
  int32_t input() { return push(-1, 0.0); }
  size_t size() const { return m_nodes.size(); }
  void clear() { m_nodes.clear(); }
  // Drops the nodes pushed after size() was `n` (a value-only evaluation undoing its recording).
  void truncate(size_t n) { m_nodes.resize(std::min(n, m_nodes.size())); }
  // Adjoints of every node given d(output)/d(output) = seed; adj.size() == size() afterwards.
  void backward(int32_t output, double seed, std::vector<double>& adj) const {
    adj.assign(m_nodes.size(), 0.0);
    if (output < 0) return;
    adj[output] = seed;
    for (int32_t i = output; i >= 0; --i) {
      const double g = adj[i];
      if (g == 0.0) continue;
      const Node& n = m_nodes[i];
      if (n.a >= 0) adj[n.a] += g * n.da;
      if (n.b >= 0) adj[n.b] += g * n.db;
    }
  }
  static Tape& current() {
    // initial-exec: every tape operation looks this up; the default model for shared libraries
    // goes through __tls_get_addr, measured at ~15% of render_backward. The tape is 24 bytes,
    // well within the static TLS surplus glibc keeps for dlopen'ed libraries.
    // Under AddressSanitizer (./test.sh --sanitize) the initial-exec tape reads as a null object
    // to UBSan's checks: the default model there.
#if defined(__linux__) && defined(__GNUC__) && !defined(__SANITIZE_ADDRESS__)
    static thread_local Tape tape __attribute__((tls_model("initial-exec")));
#else
    static thread_local Tape tape;
#endif
    return tape;
  }

 private:
  std::vector<Node> m_nodes;
};

struct Var {
  double v = 0.0;
  int32_t idx = -1;  // -1: a constant

  Var() = default;
  Var(double value) : v(value) {}  // NOLINT: constants convert implicitly
  Var(double value, int32_t index) : v(value), idx(index) {}
  static Var input(double value) { return Var(value, Tape::current().input()); }
  bool is_constant() const { return idx < 0; }
};

inline Var make_unary(double v, const Var& a, double da) {
  if (a.idx < 0) return Var(v);
  return Var(v, Tape::current().push(a.idx, da));
}
inline Var make_binary(double v, const Var& a, double da, const Var& b, double db) {
  if (a.idx < 0 && b.idx < 0) return Var(v);
  if (a.idx < 0) return Var(v, Tape::current().push(b.idx, db));
  if (b.idx < 0) return Var(v, Tape::current().push(a.idx, da));
  return Var(v, Tape::current().push(a.idx, da, b.idx, db));
}

inline Var operator+(const Var& a, const Var& b) { return make_binary(a.v + b.v, a, 1.0, b, 1.0); }
inline Var operator-(const Var& a, const Var& b) { return make_binary(a.v - b.v, a, 1.0, b, -1.0); }
inline Var operator*(const Var& a, const Var& b) { return make_binary(a.v * b.v, a, b.v, b, a.v); }
inline Var operator/(const Var& a, const Var& b) {
  const double inv = 1.0 / b.v;
  return make_binary(a.v * inv, a, inv, b, -a.v * inv * inv);
}
inline Var operator-(const Var& a) { return make_unary(-a.v, a, -1.0); }
inline Var& operator+=(Var& a, const Var& b) { return a = a + b; }
inline Var& operator-=(Var& a, const Var& b) { return a = a - b; }
inline Var& operator*=(Var& a, const Var& b) { return a = a * b; }
inline Var& operator/=(Var& a, const Var& b) { return a = a / b; }
inline bool operator<(const Var& a, const Var& b) { return a.v < b.v; }
inline bool operator>(const Var& a, const Var& b) { return a.v > b.v; }
inline bool operator<=(const Var& a, const Var& b) { return a.v <= b.v; }
inline bool operator>=(const Var& a, const Var& b) { return a.v >= b.v; }

// sqrt'(0) is infinite; callers only take square roots of strictly positive quantities, and the
// derivative is guarded to stay finite (0 where the value is 0) so no NaN can reach a gradient.
inline Var sqrt(const Var& a) {
  const double s = std::sqrt(std::max(a.v, 0.0));
  return make_unary(s, a, s > 0.0 ? 0.5 / s : 0.0);
}
inline Var exp(const Var& a) {
  const double e = std::exp(a.v);
  return make_unary(e, a, e);
}
inline Var log(const Var& a) { return make_unary(std::log(a.v), a, 1.0 / a.v); }
inline Var sin(const Var& a) { return make_unary(std::sin(a.v), a, std::cos(a.v)); }
inline Var cos(const Var& a) { return make_unary(std::cos(a.v), a, -std::sin(a.v)); }
inline Var abs(const Var& a) { return make_unary(std::abs(a.v), a, a.v >= 0.0 ? 1.0 : -1.0); }
inline Var pow(const Var& a, double p) { return make_unary(std::pow(a.v, p), a, p * std::pow(a.v, p - 1.0)); }
inline Var atan(const Var& a) { return make_unary(std::atan(a.v), a, 1.0 / (1.0 + a.v * a.v)); }
inline Var atan2(const Var& y, const Var& x) {
  const double r2 = x.v * x.v + y.v * y.v;
  return make_binary(std::atan2(y.v, x.v), y, r2 > 0.0 ? x.v / r2 : 0.0, x, r2 > 0.0 ? -y.v / r2 : 0.0);
}
// acos'(+-1) is infinite: clamped to the open interval, the derivative stays finite.
inline Var acos(const Var& a) {
  const double c = std::clamp(a.v, -1.0 + 1e-12, 1.0 - 1e-12);
  return make_unary(std::acos(c), a, -1.0 / std::sqrt(1.0 - c * c));
}
inline Var max(const Var& a, const Var& b) { return a.v >= b.v ? a : b; }
inline Var min(const Var& a, const Var& b) { return a.v <= b.v ? a : b; }
inline double value(const Var& a) { return a.v; }
inline double value(double a) { return a; }

// The same spellings for plain doubles, so templated code instantiates with T = double (used for
// finite-difference references) and T = Var.
using std::abs;
using std::acos;
using std::atan;
using std::atan2;
using std::cos;
using std::exp;
using std::log;
using std::max;
using std::min;
using std::pow;
using std::sin;
using std::sqrt;

// ---- small 3-vectors over T ------------------------------------------------------------------------
template <typename T>
struct V3 {
  T x, y, z;
  V3() : x(0.0), y(0.0), z(0.0) {}
  V3(T a, T b, T c) : x(a), y(b), z(c) {}
  template <typename U>
  explicit V3(const U& u) : x(double(u.x)), y(double(u.y)), z(double(u.z)) {}
  T operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
};
template <typename T> V3<T> operator+(const V3<T>& a, const V3<T>& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
template <typename T> V3<T> operator-(const V3<T>& a, const V3<T>& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
template <typename T> V3<T> operator-(const V3<T>& a) { return {-a.x, -a.y, -a.z}; }
template <typename T> V3<T> operator*(const V3<T>& a, const T& s) { return {a.x * s, a.y * s, a.z * s}; }
template <typename T> V3<T> operator*(const T& s, const V3<T>& a) { return {a.x * s, a.y * s, a.z * s}; }
template <typename T> V3<T> operator*(const V3<T>& a, const V3<T>& b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
template <typename T> V3<T> operator/(const V3<T>& a, const T& s) { return {a.x / s, a.y / s, a.z / s}; }
template <typename T> T dot(const V3<T>& a, const V3<T>& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
template <typename T> V3<T> cross(const V3<T>& a, const V3<T>& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <typename T> T length(const V3<T>& a) { return sqrt(dot(a, a)); }
template <typename T> V3<T> normalize(const V3<T>& a) { return a / length(a); }
template <typename T> V3<double> values(const V3<T>& a) { return {value(a.x), value(a.y), value(a.z)}; }

}  // namespace limn::ad

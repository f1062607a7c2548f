// Piecewise-constant distributions on [0,1) and [0,1)^2, sampled by inverting the CDF.
#pragma once
#include <stdexcept>
#include <vector>
#include "core/math/vec.h"

namespace limn {

class Distribution1D {
 public:
  Distribution1D() = default;
  explicit Distribution1D(std::vector<float> weights) : m_func(std::move(weights)) {
    if (m_func.empty()) throw std::invalid_argument("Distribution1D: no weights");
    m_cdf.assign(m_func.size() + 1, 0.0);
    for (size_t i = 0; i < m_func.size(); ++i) {
      if (!(m_func[i] >= 0.0f) || !std::isfinite(m_func[i]))
        throw std::invalid_argument("Distribution1D: weight " + std::to_string(i) + " is negative or not finite");
      m_cdf[i + 1] = m_cdf[i] + m_func[i];
    }
    m_integral = m_cdf.back() / double(m_func.size());
    if (m_cdf.back() <= 0.0) {  // all zero: fall back to uniform so sampling stays defined
      for (size_t i = 0; i <= m_func.size(); ++i) m_cdf[i] = double(i) / double(m_func.size());
      m_all_zero = true;
    } else {
      for (auto& c : m_cdf) c /= m_cdf.back();
    }
  }
  size_t size() const { return m_func.size(); }
  // Mean of the weights (the integral of the step function over [0,1)).
  double integral() const { return m_integral; }
  // Probability of choosing bin i.
  float pmf(size_t i) const { return float(m_cdf[i + 1] - m_cdf[i]); }
  // The probability of bins [0, i) (i <= size()).
  double cdf(size_t i) const { return m_cdf[i]; }
  // Density on [0,1) of the continuous sample.
  float pdf(float x) const {
    const size_t i = std::min<size_t>(size_t(std::max(x, 0.0f) * m_func.size()), m_func.size() - 1);
    return pmf(i) * float(m_func.size());
  }
  // Samples a bin and a continuous offset; returns x in [0,1) with density pdf(x).
  float sample_continuous(float u, size_t* bin = nullptr, float* pdf_out = nullptr) const {
    const size_t i = sample_discrete(u);
    const double lo = m_cdf[i], hi = m_cdf[i + 1];
    double du = hi > lo ? (double(u) - lo) / (hi - lo) : 0.5;
    du = std::clamp(du, 0.0, 1.0 - 1e-7);  // keep x strictly inside bin i
    if (bin) *bin = i;
    if (pdf_out) *pdf_out = pmf(i) * float(m_func.size());
    // Stay inside bin i after rounding to float.
    const float x = float((double(i) + du) / double(m_func.size()));
    return std::min(x, std::nextafter(float(double(i + 1) / double(m_func.size())), 0.0f));
  }
  // Picks bin i for u and returns where u fell inside bin i's share of [0,1), rescaled to [0,1):
  // a second uniform number for free, so a 1D sample chooses both the bin and a point inside it.
  // The offset has the resolution of u divided by the bin's probability: a float u (24 bits)
  // leaves a bin of probability p only p 2^24 distinct offsets, so callers that place points
  // inside small-probability bins pass a double (Pcg32::next_double).
  double sample_remapped(double u, size_t* bin) const {
    const size_t i = sample_discrete(u);
    *bin = i;
    const double lo = m_cdf[i], hi = m_cdf[i + 1];
    const double f = hi > lo ? (u - lo) / (hi - lo) : 0.5;
    return std::clamp(f, 0.0, std::nextafter(1.0, 0.0));
  }
  // Inverse of sample_remapped: the u that picks bin i with remapped offset f.
  float invert_remapped(size_t i, float f) const {
    const double u = m_cdf[i] + double(f) * (m_cdf[i + 1] - m_cdf[i]);
    return std::min(float(u), std::nextafter(float(m_cdf[i + 1]), 0.0f));
  }
  size_t sample_discrete(double u) const {
    // First i with cdf[i+1] > u, skipping empty bins.
    auto it = std::upper_bound(m_cdf.begin() + 1, m_cdf.end(), u);
    size_t i = size_t(it - m_cdf.begin()) - 1;
    if (i >= m_func.size()) i = m_func.size() - 1;
    while (i > 0 && pmf(i) == 0.0f) --i;
    return i;
  }
  bool all_zero() const { return m_all_zero; }

 private:
  std::vector<float> m_func;
  std::vector<double> m_cdf;
  double m_integral = 0.0;
  bool m_all_zero = false;
};

// Row-major 2D distribution: marginal over rows (v), conditional over columns (u) per row.
class Distribution2D {
 public:
  Distribution2D() = default;
  Distribution2D(const std::vector<float>& weights, int width, int height) : m_width(width), m_height(height) {
    std::vector<float> row_mass(height);
    for (int y = 0; y < height; ++y) {
      std::vector<float> row(weights.begin() + size_t(y) * width, weights.begin() + size_t(y + 1) * width);
      m_rows.emplace_back(row);
      row_mass[y] = float(m_rows.back().integral());
    }
    m_marginal = Distribution1D(row_mass);
  }
  // Returns (u, v) in [0,1)^2 and its density with respect to the unit square.
  Vec2 sample(const Vec2& u, float* pdf) const {
    size_t row;
    float pdf_v, pdf_u;
    const float v = m_marginal.sample_continuous(u.y, &row, &pdf_v);
    const float x = m_rows[row].sample_continuous(u.x, nullptr, &pdf_u);
    *pdf = pdf_u * pdf_v;
    return Vec2(x, v);
  }
  float pdf(const Vec2& p) const {
    const int y = std::clamp(int(p.y * m_height), 0, m_height - 1);
    return m_marginal.pdf(p.y) * m_rows[y].pdf(p.x);
  }
  int width() const { return m_width; }
  int height() const { return m_height; }

 private:
  int m_width = 0, m_height = 0;
  std::vector<Distribution1D> m_rows;
  Distribution1D m_marginal;
};

}  // namespace limn

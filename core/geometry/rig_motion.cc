#include "core/geometry/rig_motion.h"

#include <cmath>
#include <limits>

#include <opencv2/calib3d.hpp>

namespace recog {
namespace {

// Errors beyond this (pixels) count as this: a degenerate motion must not make the cost infinite.
constexpr double kMaxErrorPx = 1e6;

cv::Matx33d Skew(const cv::Vec3d& v) { return {0, -v[2], v[1], v[2], 0, -v[0], -v[1], v[0], 0}; }

// Huber's cost of an error, and the weight that turns it into a least-squares residual.
double HuberCost(double r, double k) {
  const double a = std::abs(r);
  return a <= k ? r * r : 2 * k * a - k * k;
}

double TotalCost(std::span<const RigPairRays> pairs, const cv::Matx33d& R, const cv::Vec3d& t,
                 double huber_px, std::vector<double>* scratch) {
  double cost = 0;
  for (const RigPairRays& pair : pairs) {
    RigPairEpipolarErrors(pair, R, t, scratch);
    for (double e : *scratch) cost += HuberCost(e, huber_px);
  }
  return cost;
}

// The robustly weighted residuals of every correspondence at (exp(w) R0, t).
void Residuals(std::span<const RigPairRays> pairs, const cv::Matx33d& R0, const cv::Vec6d& p,
               const std::vector<double>& weights, std::vector<double>* out,
               std::vector<double>* scratch) {
  cv::Matx33d turn;
  cv::Rodrigues(cv::Vec3d(p[0], p[1], p[2]), turn);
  const cv::Matx33d R = turn * R0;
  const cv::Vec3d t(p[3], p[4], p[5]);
  out->clear();
  for (const RigPairRays& pair : pairs) {
    RigPairEpipolarErrors(pair, R, t, scratch);
    for (double e : *scratch) out->push_back(e * weights[out->size()]);
  }
}

}  // namespace

void RigPairEpipolarErrors(const RigPairRays& pair, const cv::Matx33d& R, const cv::Vec3d& t,
                           std::vector<double>* errors_px) {
  const cv::Matx33d R_p = pair.query_R.t() * R * pair.match_R;
  const cv::Vec3d t_p = pair.query_R.t() * (R * pair.match_t + t - pair.query_t);
  const cv::Matx33d E = Skew(t_p) * R_p;
  errors_px->resize(pair.query.size());
  for (size_t i = 0; i < pair.query.size(); ++i) {
    const cv::Vec3d line_in_query = E * pair.match[i];
    const cv::Vec3d line_in_match = E.t() * pair.query[i];
    const double residual = pair.query[i].dot(line_in_query);
    const double norm2 = line_in_query[0] * line_in_query[0] + line_in_query[1] * line_in_query[1] +
                         line_in_match[0] * line_in_match[0] + line_in_match[1] * line_in_match[1];
    const double error = norm2 > 0 ? pair.focal_px * residual / std::sqrt(norm2) : kMaxErrorPx;
    (*errors_px)[i] = std::clamp(error, -kMaxErrorPx, kMaxErrorPx);
  }
}

void RefineRigMotion(std::span<const RigPairRays> pairs, double huber_px, cv::Matx33d* R,
                     cv::Vec3d* t) {
  std::vector<double> scratch, residuals, shifted, weights;
  cv::Matx33d R0 = *R;
  cv::Vec6d p(0, 0, 0, (*t)[0], (*t)[1], (*t)[2]);
  double lambda = 1e-3;
  bool converged = false;
  for (int iteration = 0; iteration < 30 && !converged; ++iteration) {
    // Weights of the current point (iteratively reweighted least squares for Huber's cost).
    weights.clear();
    cv::Matx33d turn;
    cv::Rodrigues(cv::Vec3d(p[0], p[1], p[2]), turn);
    for (const RigPairRays& pair : pairs) {
      RigPairEpipolarErrors(pair, turn * R0, cv::Vec3d(p[3], p[4], p[5]), &scratch);
      for (double e : scratch) {
        const double a = std::abs(e);
        weights.push_back(a <= huber_px ? 1.0 : std::sqrt(huber_px / a));
      }
    }
    Residuals(pairs, R0, p, weights, &residuals, &scratch);
    // Forward-difference Jacobian, 6 columns.
    const size_t n = residuals.size();
    cv::Mat J(int(n), 6, CV_64F);
    for (int k = 0; k < 6; ++k) {
      cv::Vec6d q = p;
      const double h = 1e-7 * std::max(1.0, std::abs(p[k]));
      q[k] += h;
      Residuals(pairs, R0, q, weights, &shifted, &scratch);
      for (size_t i = 0; i < n; ++i) J.at<double>(int(i), k) = (shifted[i] - residuals[i]) / h;
    }
    const cv::Mat r(int(n), 1, CV_64F, residuals.data());
    const cv::Mat JtJ = J.t() * J, Jtr = J.t() * r;
    const double cost = r.dot(r);
    bool improved = false;
    for (int attempt = 0; attempt < 10 && !improved; ++attempt) {
      cv::Mat A = JtJ.clone();
      for (int k = 0; k < 6; ++k) A.at<double>(k, k) *= 1.0 + lambda;
      cv::Mat step;
      if (!cv::solve(A, -Jtr, step, cv::DECOMP_CHOLESKY)) {
        lambda *= 10;
        continue;
      }
      cv::Vec6d q = p;
      for (int k = 0; k < 6; ++k) q[k] += step.at<double>(k);
      Residuals(pairs, R0, q, weights, &shifted, &scratch);
      double new_cost = 0;
      for (double v : shifted) new_cost += v * v;
      if (new_cost < cost) {
        improved = true;
        p = q;
        lambda = std::max(lambda / 10, 1e-9);
        converged = cv::norm(step) < 1e-10;
      } else {
        lambda *= 10;
      }
    }
    if (!improved) break;
    // Fold the rotation into R0 so that the next linearisation starts from zero.
    cv::Matx33d folded;
    cv::Rodrigues(cv::Vec3d(p[0], p[1], p[2]), folded);
    R0 = folded * R0;
    p[0] = p[1] = p[2] = 0;
  }
  *R = R0;
  *t = cv::Vec3d(p[3], p[4], p[5]);
}

cv::Vec3d InitialRigTranslation(std::span<const RigPairRays> pairs, size_t reference,
                                const cv::Vec3d& direction, const cv::Matx33d& R, double huber_px) {
  const RigPairRays& pair = pairs[reference];
  const cv::Vec3d base = pair.query_t - R * pair.match_t;
  const cv::Vec3d step = pair.query_R * direction;
  std::vector<double> scratch;
  cv::Vec3d best = base + step;
  double best_cost = std::numeric_limits<double>::infinity();
  for (double scale = 0.05; scale <= 50.0; scale *= 1.25) {
    const cv::Vec3d t = base + scale * step;
    const double cost = TotalCost(pairs, R, t, huber_px, &scratch);
    if (cost < best_cost) {
      best_cost = cost;
      best = t;
    }
  }
  return best;
}

}  // namespace recog

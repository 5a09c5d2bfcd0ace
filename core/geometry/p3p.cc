#include "core/geometry/p3p.h"

#include <algorithm>
#include <cmath>

namespace recog {
namespace {

// Relative error of a squared side length of the camera-frame triangle that a solution may have.
constexpr double kSideTolerance = 1e-4;

// A polynomial of degree < N, coefficients from the constant term up.
template <size_t N>
using Poly = std::array<double, N>;

template <size_t A, size_t B>
Poly<A + B - 1> Multiply(const Poly<A>& a, const Poly<B>& b) {
  Poly<A + B - 1> product{};
  for (size_t i = 0; i < A; ++i) {
    for (size_t j = 0; j < B; ++j) product[i + j] += a[i] * b[j];
  }
  return product;
}

double EvaluateQuartic(const Poly<5>& q, double x) {
  return (((q[4] * x + q[3]) * x + q[2]) * x + q[1]) * x + q[0];
}

double QuarticSlope(const Poly<5>& q, double x) {
  return ((4 * q[4] * x + 3 * q[3]) * x + 2 * q[2]) * x + q[1];
}

// The largest real root of x^3 + a x^2 + b x + c.
double LargestCubicRoot(double a, double b, double c) {
  const double shift = a / 3;
  const double p = b - a * shift;                              // depressed: z^3 + p z + q
  const double q = 2 * shift * shift * shift - b * shift + c;  // with x = z - a / 3
  const double half_q = q / 2;
  const double third_p = p / 3;
  const double discriminant = half_q * half_q + third_p * third_p * third_p;
  double z;
  if (discriminant >= 0) {
    const double root = std::sqrt(discriminant);
    z = std::cbrt(-half_q + root) + std::cbrt(-half_q - root);
  } else {  // three real roots: the trigonometric form; k = 0 is the largest
    const double radius = std::sqrt(-third_p);
    const double cosine = std::clamp(-half_q / (radius * radius * radius), -1.0, 1.0);
    z = 2 * radius * std::cos(std::acos(cosine) / 3);
  }
  double x = z - shift;
  // One Newton step against the rounding of the closed form.
  const double value = ((x + a) * x + b) * x + c;
  const double slope = (3 * x + 2 * a) * x + b;
  if (slope != 0) x -= value / slope;
  return x;
}

// The real roots of q[4] x^4 + ... + q[0] (Ferrari), each polished by Newton steps; returns how
// many it wrote to roots.
size_t RealQuarticRoots(const Poly<5>& q, std::array<double, 4>* roots) {
  const double scale =
      std::max({std::abs(q[0]), std::abs(q[1]), std::abs(q[2]), std::abs(q[3]), std::abs(q[4])});
  if (!(scale > 0) || std::abs(q[4]) < 1e-12 * scale) return 0;
  const double a = q[3] / q[4], b = q[2] / q[4], c = q[1] / q[4], d = q[0] / q[4];
  // Depressed quartic y^4 + p y^2 + r1 y + r0 with x = y - a / 4.
  const double shift = a / 4;
  const double a2 = a * a;
  const double p = b - 3 * a2 / 8;
  const double r1 = c - a * b / 2 + a2 * a / 8;
  const double r0 = d - a * c / 4 + a2 * b / 16 - 3 * a2 * a2 / 256;
  std::array<double, 4> depressed;
  size_t count = 0;
  auto add_quadratic_roots = [&](double linear, double constant) {
    const double discriminant = linear * linear - 4 * constant;
    if (discriminant < 0) return;
    const double root = std::sqrt(discriminant);
    depressed[count++] = (-linear + root) / 2;
    depressed[count++] = (-linear - root) / 2;
  };
  if (std::abs(r1) < 1e-14 * std::max(1.0, std::abs(r0))) {
    // Biquadratic: y^2 = z with z^2 + p z + r0 = 0.
    const double discriminant = p * p - 4 * r0;
    if (discriminant >= 0) {
      for (const double z :
           {(-p + std::sqrt(discriminant)) / 2, (-p - std::sqrt(discriminant)) / 2}) {
        if (z >= 0) {
          depressed[count++] = std::sqrt(z);
          depressed[count++] = -std::sqrt(z);
        }
      }
    }
  } else {
    // (y^2 + p/2 + m)^2 = 2m (y - r1 / (4m))^2 for the root m > 0 of the resolvent cubic
    // 8m^3 + 8p m^2 + (2p^2 - 8 r0) m - r1^2 = 0, so the quartic splits into two quadratics.
    const double m = LargestCubicRoot(p, p * p / 4 - r0, -r1 * r1 / 8);
    if (!(m > 0)) return 0;
    const double root_2m = std::sqrt(2 * m);
    for (const double sign : {1.0, -1.0}) {
      add_quadratic_roots(-sign * root_2m, p / 2 + m + sign * r1 / (2 * root_2m));
    }
  }
  for (size_t i = 0; i < count; ++i) {
    double x = depressed[i] - shift;
    for (int step = 0; step < 4; ++step) {
      const double slope = QuarticSlope(q, x);
      if (slope == 0) break;
      const double change = EvaluateQuartic(q, x) / slope;
      x -= change;
      if (std::abs(change) <= 1e-15 * std::max(1.0, std::abs(x))) break;
    }
    (*roots)[i] = x;
  }
  return count;
}

// Columns: the unit edge p1 -> p2, the unit normal of the triangle (p1, p2, p3) crossed with it,
// and the normal. False for a degenerate triangle.
bool TriangleFrame(const cv::Vec3d& p1, const cv::Vec3d& p2, const cv::Vec3d& p3,
                   cv::Matx33d* frame) {
  const cv::Vec3d edge = p2 - p1;
  const cv::Vec3d normal = edge.cross(p3 - p1);
  const double edge_norm = cv::norm(edge), normal_norm = cv::norm(normal);
  if (!(edge_norm > 0) || !(normal_norm > 1e-12 * edge_norm * edge_norm)) return false;
  const cv::Vec3d e1 = edge / edge_norm;
  const cv::Vec3d e3 = normal / normal_norm;
  const cv::Vec3d e2 = e3.cross(e1);
  *frame = cv::Matx33d(e1[0], e2[0], e3[0], e1[1], e2[1], e3[1], e1[2], e2[2], e3[2]);
  return true;
}

}  // namespace

size_t SolveP3P(const std::array<cv::Vec3d, 3>& object, const std::array<cv::Vec3d, 3>& rays,
                std::array<P3PSolution, 4>* solutions) {
  cv::Matx33d object_frame;
  if (!TriangleFrame(object[0], object[1], object[2], &object_frame)) return 0;
  std::array<cv::Vec3d, 3> j;
  for (size_t i = 0; i < 3; ++i) {
    const double length = cv::norm(rays[i]);
    if (!(length > 0)) return 0;
    j[i] = rays[i] / length;
  }
  // Side lengths opposite each point and the cosines of the angles between the rays.
  const double a2 = cv::normL2Sqr<double, double>((object[1] - object[2]).val, 3);
  const double b2 = cv::normL2Sqr<double, double>((object[0] - object[2]).val, 3);
  const double c2 = cv::normL2Sqr<double, double>((object[0] - object[1]).val, 3);
  const double cos_alpha = j[1].dot(j[2]), cos_beta = j[0].dot(j[2]), cos_gamma = j[0].dot(j[1]);
  // Depths s1, s2 = u s1, s3 = v s1. The law of cosines on the three sides gives
  //   b^2 (1 + u^2 - 2u cos_gamma) = c^2 (1 + v^2 - 2v cos_beta)            (A)
  //   b^2 (u^2 + v^2 - 2uv cos_alpha) = a^2 (1 + v^2 - 2v cos_beta)         (B)
  // (A) - (B) is linear in u: u = N(v) / D(v); put back into (A) times D^2, a quartic in v.
  const double k = (c2 - a2) / b2;
  const Poly<3> n = {k - 1, -2 * k * cos_beta, 1 + k};
  const Poly<2> d = {-2 * cos_gamma, 2 * cos_alpha};
  const Poly<3> w = {1 - c2 / b2, 2 * cos_beta * c2 / b2, -c2 / b2};
  const Poly<5> nn = Multiply(n, n);
  const Poly<4> nd = Multiply(n, d);
  const Poly<5> wdd = Multiply(w, Multiply(d, d));
  Poly<5> quartic{};
  for (size_t i = 0; i < 5; ++i) quartic[i] = nn[i] + wdd[i] - (i < 4 ? 2 * cos_gamma * nd[i] : 0);

  std::array<double, 4> roots;
  const size_t root_count = RealQuarticRoots(quartic, &roots);
  size_t count = 0;
  for (size_t r = 0; r < root_count; ++r) {
    const double v = roots[r];
    const double denominator = d[0] + d[1] * v;
    if (std::abs(denominator) < 1e-12) continue;
    const double u = (n[0] + (n[1] + n[2] * v) * v) / denominator;
    const double s1_squared = b2 / (1 + v * v - 2 * v * cos_beta);
    if (!(s1_squared > 0) || !(u > 0) || !(v > 0)) continue;
    const double s1 = std::sqrt(s1_squared);
    const cv::Vec3d camera1 = s1 * j[0], camera2 = u * s1 * j[1], camera3 = v * s1 * j[2];
    // A root that rounding made (a complex pair near the real axis) or left inaccurate gives a
    // triangle of other side lengths than the object's: not a solution.
    const auto off = [](const cv::Vec3d& p, const cv::Vec3d& q, double length2) {
      return std::abs(cv::normL2Sqr<double, double>((p - q).val, 3) - length2) >
             kSideTolerance * length2;
    };
    if (off(camera2, camera3, a2) || off(camera1, camera3, b2) || off(camera1, camera2, c2)) {
      continue;
    }
    cv::Matx33d camera_frame;
    if (!TriangleFrame(camera1, camera2, camera3, &camera_frame)) continue;
    P3PSolution& solution = (*solutions)[count++];
    solution.R = camera_frame * object_frame.t();
    solution.t = camera1 - solution.R * object[0];
  }
  return count;
}

}  // namespace recog

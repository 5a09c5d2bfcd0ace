#include "core/geometry/camera_model.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "core/common/text_lines.h"

namespace recog {
namespace {

struct LensAlias {
  std::string_view name;
  LensModel lens;
};

// The names ParseLensModel takes, each lens's own name first.
constexpr std::array<LensAlias, 10> kLensAliases = {{
    {"radtan", LensModel::kRadialTangential},
    {"plumb_bob", LensModel::kRadialTangential},
    {"rational_polynomial", LensModel::kRadialTangential},
    {"radial-tangential", LensModel::kRadialTangential},
    {"equidistant", LensModel::kEquidistant},
    {"equi", LensModel::kEquidistant},
    {"fisheye", LensModel::kEquidistant},
    {"kannala_brandt", LensModel::kEquidistant},
    {"double_sphere", LensModel::kDoubleSphere},
    {"ds", LensModel::kDoubleSphere},
}};

bool IsKnownLens(LensModel lens) {
  switch (lens) {
    case LensModel::kRadialTangential:
    case LensModel::kEquidistant:
    case LensModel::kDoubleSphere:
      return true;
  }
  return false;
}

// Whether `lens` takes `count` coefficients (none: a pinhole camera).
bool TakesCoefficientCount(LensModel lens, size_t count) {
  switch (lens) {
    case LensModel::kRadialTangential:
      return count == 0 || count == 4 || count == 5 || count == 8 || count == 12 || count == 14;
    case LensModel::kEquidistant:
      return count == 0 || count == 4;
    case LensModel::kDoubleSphere:
      return count == 0 || count == 2;
  }
  return false;
}

// The plain pinhole: the normalised point is the direction divided by its depth.
struct PinholeLens {
  bool Project(const cv::Vec3d& p, cv::Vec2d* m) const {
    if (!(p[2] > 0)) return false;
    *m = {p[0] / p[2], p[1] / p[2]};
    return true;
  }
  bool Unproject(const cv::Vec2d& m, cv::Vec3d* bearing) const {
    *bearing = {m[0], m[1], 1};
    return true;
  }
};

// The homography of OpenCV's tilted sensor (calib3d's documentation): the rotation
// R = R_y(ty) R_x(tx), then the projection back onto the plane z = 1 along the optical axis.
cv::Matx33d TiltHomography(double tx, double ty) {
  const double ctx = std::cos(tx), stx = std::sin(tx), cty = std::cos(ty), sty = std::sin(ty);
  const cv::Matx33d about_x(1, 0, 0, 0, ctx, stx, 0, -stx, ctx);
  const cv::Matx33d about_y(cty, 0, -sty, 0, 1, 0, sty, 0, cty);
  const cv::Matx33d r = about_y * about_x;
  const cv::Matx33d onto_plane(r(2, 2), 0, -r(0, 2), 0, r(2, 2), -r(1, 2), 0, 0, 1);
  return onto_plane * r;
}

// OpenCV's radial-tangential family: a rational radial factor, tangential and thin prism terms,
// then the tilt homography; missing coefficients are 0.
class RadtanLens {
 public:
  explicit RadtanLens(const std::vector<double>& coefficients) {
    std::copy_n(coefficients.begin(), std::min(coefficients.size(), c_.size()), c_.begin());
    tilted_ = c_[12] != 0 || c_[13] != 0;
    if (tilted_) {
      tilt_ = TiltHomography(c_[12], c_[13]);
      untilt_ = tilt_.inv();
    }
  }

  bool Project(const cv::Vec3d& p, cv::Vec2d* m) const {
    if (!(p[2] > 0)) return false;
    *m = Distort({p[0] / p[2], p[1] / p[2]}, nullptr);
    if (tilted_ && !Homography(tilt_, *m, m)) return false;
    return std::isfinite((*m)[0]) && std::isfinite((*m)[1]);
  }

  // Newton's method on Distort(x) = m from x = m, each step halved until the residual shrinks.
  // Only a solution where the distortion keeps its orientation (a positive Jacobian) counts:
  // beyond a fold of the lens the same pixel has another, spurious, preimage.
  bool Unproject(const cv::Vec2d& m, cv::Vec3d* bearing) const {
    constexpr int kMaxIterations = 50;
    constexpr double kTolerance = 1e-10;  // on the normalised plane
    cv::Vec2d target = m;
    if (tilted_ && !Homography(untilt_, m, &target)) return false;
    cv::Vec2d x = target;
    cv::Matx22d jacobian;
    cv::Vec2d residual = Distort(x, &jacobian) - target;
    for (int i = 0; i < kMaxIterations; ++i) {
      const double det = cv::determinant(jacobian);
      if (cv::norm(residual) < kTolerance) {
        if (!(det > 0)) return false;
        *bearing = {x[0], x[1], 1};
        return true;
      }
      if (det == 0) return false;
      const cv::Vec2d step((jacobian(1, 1) * residual[0] - jacobian(0, 1) * residual[1]) / det,
                           (jacobian(0, 0) * residual[1] - jacobian(1, 0) * residual[0]) / det);
      double scale = 1;
      for (;;) {
        const cv::Vec2d candidate = x - scale * step;
        cv::Matx22d candidate_jacobian;
        const cv::Vec2d candidate_residual = Distort(candidate, &candidate_jacobian) - target;
        if (cv::norm(candidate_residual) < cv::norm(residual)) {
          x = candidate;
          residual = candidate_residual;
          jacobian = candidate_jacobian;
          break;
        }
        scale /= 2;
        if (scale < 1e-6) return false;
      }
    }
    return false;
  }

 private:
  // The homogeneous map h applied to the point m of the plane; false when it goes to infinity or
  // behind.
  static bool Homography(const cv::Matx33d& h, const cv::Vec2d& m, cv::Vec2d* out) {
    const cv::Vec3d q = h * cv::Vec3d(m[0], m[1], 1);
    if (!(q[2] > 0)) return false;
    *out = {q[0] / q[2], q[1] / q[2]};
    return true;
  }

  // The distorted normalised point of x (before the tilt), and its Jacobian when asked. With
  // r² = a² + b², every term but the tangential ones depends on (a, b) through r², whence the
  // 2a and 2b factors of the derivatives.
  cv::Vec2d Distort(const cv::Vec2d& x, cv::Matx22d* jacobian) const {
    const auto& [k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4, tx, ty] = c_;
    const double a = x[0], b = x[1];
    const double r2 = a * a + b * b;
    const double num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3));
    const double den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6));
    const double radial = num / den;
    const cv::Vec2d distorted(
        a * radial + 2 * p1 * a * b + p2 * (r2 + 2 * a * a) + r2 * (s1 + r2 * s2),
        b * radial + p1 * (r2 + 2 * b * b) + 2 * p2 * a * b + r2 * (s3 + r2 * s4));
    if (jacobian != nullptr) {
      const double dnum = k1 + r2 * (2 * k2 + 3 * k3 * r2);  // d/dr² of each
      const double dden = k4 + r2 * (2 * k5 + 3 * k6 * r2);
      const double dradial = (dnum * den - num * dden) / (den * den);
      const double dprism_x = s1 + 2 * s2 * r2, dprism_y = s3 + 2 * s4 * r2;
      *jacobian = cv::Matx22d(radial + 2 * a * (a * dradial + dprism_x) + 2 * p1 * b + 6 * p2 * a,
                              2 * b * (a * dradial + dprism_x) + 2 * p1 * a + 2 * p2 * b,
                              2 * a * (b * dradial + dprism_y) + 2 * p1 * a + 2 * p2 * b,
                              radial + 2 * b * (b * dradial + dprism_y) + 6 * p1 * b + 2 * p2 * a);
    }
    return distorted;
  }

  std::array<double, 14> c_{};  // k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4 tx ty
  bool tilted_ = false;
  cv::Matx33d tilt_, untilt_;
};

// Kannala–Brandt as cv::fisheye: a direction θ off the axis lands at radius θd(θ) on the
// normalised plane, in the direction's azimuth. The model holds while θd grows.
class EquidistantLens {
 public:
  explicit EquidistantLens(const std::vector<double>& coefficients) {
    std::copy_n(coefficients.begin(), std::min(coefficients.size(), k_.size()), k_.begin());
    max_theta_ = FirstFold();
    max_theta_d_ = ThetaD(max_theta_);
  }

  bool Project(const cv::Vec3d& p, cv::Vec2d* m) const {
    const double rho = std::hypot(p[0], p[1]);
    const double theta = std::atan2(rho, p[2]);
    if (!(theta < max_theta_)) return false;
    // On the axis θd/ρ tends to 1/z, and the point to the centre either way.
    *m = rho > 0 ? cv::Vec2d(p[0], p[1]) * (ThetaD(theta) / rho) : cv::Vec2d(0, 0);
    return true;
  }

  bool Unproject(const cv::Vec2d& m, cv::Vec3d* bearing) const {
    const double theta_d = std::hypot(m[0], m[1]);
    if (theta_d == 0) {
      *bearing = {0, 0, 1};
      return true;
    }
    double theta = 0;
    if (!(theta_d < max_theta_d_) || !SolveTheta(theta_d, &theta)) return false;
    const double s = std::sin(theta) / theta_d;
    *bearing = {s * m[0], s * m[1], std::cos(theta)};
    return true;
  }

 private:
  double ThetaD(double theta) const {
    const double t2 = theta * theta;
    return theta * (1 + t2 * (k_[0] + t2 * (k_[1] + t2 * (k_[2] + t2 * k_[3]))));
  }
  double Slope(double theta) const {  // dθd/dθ
    const double t2 = theta * theta;
    return 1 + t2 * (3 * k_[0] + t2 * (5 * k_[1] + t2 * (7 * k_[2] + t2 * 9 * k_[3])));
  }

  // The first angle in (0, π] where θd stops growing, else π: the slope is sampled to its first
  // non-positive value, then the sign change is bisected.
  double FirstFold() const {
    constexpr int kSamples = 64;
    double below = 0;
    for (int i = 1; i <= kSamples; ++i) {
      double above = CV_PI * i / kSamples;
      if (Slope(above) <= 0) {
        for (int j = 0; j < 60; ++j) {
          const double mid = 0.5 * (below + above);
          (Slope(mid) > 0 ? below : above) = mid;
        }
        return below;
      }
      below = above;
    }
    return CV_PI;
  }

  // θ in [0, max θ) with θd(θ) = theta_d: Newton's method kept inside a shrinking bracket,
  // bisecting when a step would leave it.
  bool SolveTheta(double theta_d, double* theta) const {
    constexpr int kMaxIterations = 100;
    constexpr double kTolerance = 1e-12;
    double low = 0, high = max_theta_;
    double t = theta_d < high ? theta_d : 0.5 * (low + high);
    for (int i = 0; i < kMaxIterations; ++i) {
      const double error = ThetaD(t) - theta_d;
      if (std::abs(error) < kTolerance) {
        *theta = t;
        return true;
      }
      (error > 0 ? high : low) = t;
      const double next = t - error / Slope(t);
      t = next > low && next < high ? next : 0.5 * (low + high);
    }
    return false;
  }

  std::array<double, 4> k_{};
  double max_theta_ = CV_PI;  // where the model stops
  double max_theta_d_ = 0;    // the radius of the image there
};

// Usenko et al.'s double sphere: the point goes onto a unit sphere, then onto a second one
// shifted by xi along the axis, then through a pinhole shifted by alpha / (1 - alpha).
class DoubleSphereLens {
 public:
  explicit DoubleSphereLens(const std::vector<double>& coefficients)
      : xi_(coefficients.size() > 0 ? coefficients[0] : 0),
        alpha_(coefficients.size() > 1 ? coefficients[1] : 0) {
    // The paper's valid region: the projection is one-to-one for directions with z > -w2 |p|.
    const double w1 = alpha_ <= 0.5 ? alpha_ / (1 - alpha_) : (1 - alpha_) / alpha_;
    w2_ = (w1 + xi_) / std::sqrt(2 * w1 * xi_ + xi_ * xi_ + 1);
  }

  bool Project(const cv::Vec3d& p, cv::Vec2d* m) const {
    const double d1 = cv::norm(p);
    if (!(p[2] > -w2_ * d1)) return false;
    const double shifted_z = xi_ * d1 + p[2];
    const double d2 = std::sqrt(p[0] * p[0] + p[1] * p[1] + shifted_z * shifted_z);
    const double depth = alpha_ * d2 + (1 - alpha_) * shifted_z;
    if (!(depth > 0)) return false;
    *m = {p[0] / depth, p[1] / depth};
    return true;
  }

  // The paper's closed form; a result outside Project's valid region is refused so that
  // Unproject stays Project's inverse.
  bool Unproject(const cv::Vec2d& m, cv::Vec3d* bearing) const {
    const double r2 = m[0] * m[0] + m[1] * m[1];
    const double curvature = 2 * alpha_ - 1;
    if (curvature > 0 && r2 > 1 / curvature) return false;  // outside the image circle
    const double mz =
        (1 - alpha_ * alpha_ * r2) / (alpha_ * std::sqrt(1 - curvature * r2) + 1 - alpha_);
    const double discriminant = mz * mz + (1 - xi_ * xi_) * r2;
    if (!(discriminant >= 0)) return false;
    const double scale = (mz * xi_ + std::sqrt(discriminant)) / (mz * mz + r2);
    const cv::Vec3d b(scale * m[0], scale * m[1], scale * mz - xi_);
    if (!(b[2] > -w2_ * cv::norm(b))) return false;
    *bearing = b;
    return true;
  }

 private:
  double xi_, alpha_;
  double w2_;
};

// A camera's lens with what its maps need worked out once: per ProjectDirection or
// UnprojectPixel call, or per ToPinhole batch. Pixels and normalised points are related by K.
class Lens {
 public:
  explicit Lens(const CameraIntrinsics& camera) : camera_(camera), model_(Model(camera)) {}

  bool Project(const cv::Vec3d& p, cv::Point2d* pixel) const {
    if (!(cv::norm(p) > 0)) return false;
    cv::Vec2d m;
    if (!std::visit([&](const auto& lens) { return lens.Project(p, &m); }, model_)) return false;
    *pixel = Pixel(m);
    return true;
  }

  bool Unproject(const cv::Point2d& pixel, cv::Vec3d* bearing) const {
    const cv::Vec2d m((pixel.x - camera_.cx) / camera_.fx, (pixel.y - camera_.cy) / camera_.fy);
    cv::Vec3d b;
    if (!std::visit([&](const auto& lens) { return lens.Unproject(m, &b); }, model_)) return false;
    *bearing = b / cv::norm(b);
    return true;
  }

  // The pixel of the normalised point m.
  cv::Point2d Pixel(const cv::Vec2d& m) const {
    return {camera_.fx * m[0] + camera_.cx, camera_.fy * m[1] + camera_.cy};
  }

 private:
  using AnyLens = std::variant<PinholeLens, RadtanLens, EquidistantLens, DoubleSphereLens>;

  static AnyLens Model(const CameraIntrinsics& camera) {
    if (camera.distortion.empty()) return PinholeLens();
    switch (camera.lens) {
      case LensModel::kRadialTangential:
        return RadtanLens(camera.distortion);
      case LensModel::kEquidistant:
        return EquidistantLens(camera.distortion);
      case LensModel::kDoubleSphere:
        return DoubleSphereLens(camera.distortion);
    }
    return PinholeLens();
  }

  const CameraIntrinsics& camera_;
  AnyLens model_;
};

// Moves pixels of a camera into the pinhole image of its K (see ToPinhole).
class PinholeMover {
 public:
  explicit PinholeMover(const CameraIntrinsics& camera)
      : lens_(camera), max_tangent_(std::tan(kMaxPinholeAngleDeg * CV_PI / 180.0)) {}

  void Move(cv::Point2f* pixel) const {
    cv::Vec3d b;
    if (!lens_.Unproject(cv::Point2d(*pixel), &b)) return;
    const double rho = std::hypot(b[0], b[1]);
    cv::Vec2d m;
    if (b[2] > 0 && rho <= max_tangent_ * b[2]) {
      m = {b[0] / b[2], b[1] / b[2]};
    } else if (rho > 0) {  // beyond the angle: at it, in the bearing's azimuth
      m = cv::Vec2d(b[0], b[1]) * (max_tangent_ / rho);
    } else {
      return;  // straight behind the camera: no azimuth to keep
    }
    *pixel = cv::Point2f(lens_.Pixel(m));
  }

 private:
  Lens lens_;
  double max_tangent_;
};

// The numbers, e.g. "fx,fy,cx,cy", the counts and the order each lens takes.
std::string_view LensSyntax(LensModel lens) {
  switch (lens) {
    case LensModel::kRadialTangential:
      return "fx,fy,cx,cy[,k1,k2,p1,p2[,k3[,k4,k5,k6[,s1,s2,s3,s4[,tx,ty]]]]]";
    case LensModel::kEquidistant:
      return "fx,fy,cx,cy[,k1,k2,k3,k4]";
    case LensModel::kDoubleSphere:
      return "fx,fy,cx,cy[,xi,alpha]";
  }
  return "fx,fy,cx,cy";
}

std::string_view TrimBlanks(std::string_view text) {
  while (!text.empty() && IsBlank(text.front())) text.remove_prefix(1);
  while (!text.empty() && IsBlank(text.back())) text.remove_suffix(1);
  return text;
}

}  // namespace

std::string_view LensModelName(LensModel lens) {
  switch (lens) {
    case LensModel::kRadialTangential:
      return "radtan";
    case LensModel::kEquidistant:
      return "equidistant";
    case LensModel::kDoubleSphere:
      return "double_sphere";
  }
  return "unknown";
}

StatusOr<LensModel> ParseLensModel(std::string_view name) {
  for (const LensAlias& alias : kLensAliases) {
    if (name == alias.name) return alias.lens;
  }
  std::string known;
  for (const LensAlias& alias : kLensAliases) {
    known += (known.empty() ? "" : ", ") + std::string(alias.name);
  }
  return Status::InvalidArgument("unknown lens model " + Quote(name) + " (known: " + known + ")");
}

bool CameraIntrinsics::IsPinhole() const {
  return distortion.empty() ||
         (lens == LensModel::kRadialTangential &&
          std::all_of(distortion.begin(), distortion.end(), [](double d) { return d == 0; }));
}

Status CameraIntrinsics::Validate() const {
  const bool finite =
      std::isfinite(fx) && std::isfinite(fy) && std::isfinite(cx) && std::isfinite(cy);
  if (!finite || fx <= 0 || fy <= 0) {
    return Status::InvalidArgument("camera intrinsics need finite fx, fy > 0 and finite cx, cy");
  }
  if (!IsKnownLens(lens)) {
    return Status::InvalidArgument("camera lens model " + std::to_string(int(lens)) +
                                   " is unknown");
  }
  // Radtan keeps the wording it had as the only lens.
  const std::string camera = lens == LensModel::kRadialTangential
                                 ? "camera"
                                 : std::string(LensModelName(lens)) + " camera";
  for (double d : distortion) {
    if (!std::isfinite(d)) return Status::InvalidArgument(camera + " distortion is not finite");
  }
  if (!TakesCoefficientCount(lens, distortion.size())) {
    const std::string_view counts =
        lens == LensModel::kRadialTangential ? "4, 5, 8, 12 or 14 coefficients"
        : lens == LensModel::kEquidistant    ? "4 coefficients (k1 k2 k3 k4)"
                                             : "2 coefficients (xi alpha)";
    return Status::InvalidArgument(camera + " distortion needs " + std::string(counts) + ", got " +
                                   std::to_string(distortion.size()));
  }
  if (lens == LensModel::kDoubleSphere && !distortion.empty() &&
      !(distortion[1] >= 0 && distortion[1] <= 1)) {
    return Status::InvalidArgument(camera + " needs alpha in [0, 1], got " +
                                   FormatNumber(distortion[1]));
  }
  return Status::Ok();
}

std::string CameraIntrinsics::Describe() const {
  std::string text = distortion.empty() ? "pinhole" : std::string(LensModelName(lens));
  for (const auto& [name, value] :
       {std::pair<const char*, double>{" fx=", fx}, {" fy=", fy}, {" cx=", cx}, {" cy=", cy}}) {
    text += name;
    AppendNumber(&text, value);
  }
  if (!distortion.empty()) {
    text += " [";
    for (size_t i = 0; i < distortion.size(); ++i) {
      if (i > 0) text += ' ';
      AppendNumber(&text, distortion[i]);
    }
    text += ']';
  }
  return text;
}

bool ProjectDirection(const CameraIntrinsics& camera, const cv::Vec3d& point, cv::Point2d* pixel) {
  return Lens(camera).Project(point, pixel);
}

bool UnprojectPixel(const CameraIntrinsics& camera, const cv::Point2d& pixel, cv::Vec3d* bearing) {
  return Lens(camera).Unproject(pixel, bearing);
}

void ToPinhole(const CameraIntrinsics& camera, std::span<cv::KeyPoint> keypoints) {
  if (camera.IsPinhole()) return;
  const PinholeMover mover(camera);
  for (cv::KeyPoint& keypoint : keypoints) mover.Move(&keypoint.pt);
}

void ToPinhole(const CameraIntrinsics& camera, std::span<cv::Point2f> pixels) {
  if (camera.IsPinhole()) return;
  const PinholeMover mover(camera);
  for (cv::Point2f& pixel : pixels) mover.Move(&pixel);
}

StatusOr<CameraIntrinsics> ParseCameraText(std::string_view flag, std::string_view text) {
  const auto fail = [flag](const std::string& message) {
    return Status::InvalidArgument(std::string(flag) + ": " + message);
  };
  CameraIntrinsics camera;
  bool named = false;  // a LENS: prefix
  if (const size_t colon = text.find(':'); colon != std::string_view::npos) {
    StatusOr<LensModel> lens = ParseLensModel(TrimBlanks(text.substr(0, colon)));
    if (!lens.ok()) return lens.status().WithContext(flag);
    camera.lens = *lens;
    named = true;
    text.remove_prefix(colon + 1);
  }
  std::vector<double> numbers;
  for (size_t start = 0; start <= text.size();) {
    const size_t comma = std::min(text.find(',', start), text.size());
    const std::string_view field = TrimBlanks(text.substr(start, comma - start));
    double value = 0;
    if (field.empty()) return fail("a number is missing (an empty field)");
    if (!ParseNumber(field, &value)) return fail(Quote(field) + " is not a number");
    numbers.push_back(value);
    start = comma + 1;
  }
  // Without a prefix the lens is radtan: 4 numbers a pinhole camera, more its coefficients.
  if (numbers.size() < 4 || !TakesCoefficientCount(camera.lens, numbers.size() - 4)) {
    const std::string what = named ? std::string(LensModelName(camera.lens)) + " takes " : "takes ";
    return fail(what + std::string(LensSyntax(camera.lens)) + ", got " +
                std::to_string(numbers.size()) + " numbers");
  }
  camera.fx = numbers[0];
  camera.fy = numbers[1];
  camera.cx = numbers[2];
  camera.cy = numbers[3];
  camera.distortion.assign(numbers.begin() + 4, numbers.end());
  RECOG_RETURN_IF_ERROR(camera.Validate().WithContext(flag));
  return camera;
}

}  // namespace recog

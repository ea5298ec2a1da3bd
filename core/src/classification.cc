#include "transtick/classification.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "transtick/volume.h"

namespace transtick {
namespace {

bool InUnit(float v) { return std::isfinite(v) && v >= 0.0f && v <= 1.0f; }

// Phong coefficients, the same bounds for materials and transfer functions:
// beyond them a colour is no longer finite for long (a NaN shininess, or
// ambient + diffuse near FLT_MAX, gave deposits the display refuses).
absl::Status CheckPhong(const std::string& where, float ambient, float diffuse, float specular,
                        float shininess) {
  for (float k : {ambient, diffuse, specular}) {
    if (!std::isfinite(k) || k < 0 || k > 4) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": shading coefficient ", k, " is not in [0, 4]"));
    }
  }
  if (!std::isfinite(shininess) || shininess < 1 || shininess > 1000) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, ": shininess ", shininess, " is not in [1, 1000]"));
  }
  return absl::OkStatus();
}

absl::Status CheckColor(const std::string& where, const float* c, int n) {
  for (int i = 0; i < n; ++i) {
    if (!InUnit(c[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": colour component ", i, " is ", c[i], ", must be in [0, 1]"));
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status Classification::Validate() const {
  if (materials.empty()) return absl::InvalidArgumentError("materials: none given");
  if (materials.size() > kMaxMaterials) {
    return absl::InvalidArgumentError(
        absl::StrCat("materials: ", materials.size(), " given, at most ", kMaxMaterials));
  }
  for (size_t i = 0; i < materials.size(); ++i) {
    const Material& m = materials[i];
    std::string where =
        absl::StrCat("material ", i, m.name.empty() ? "" : " '", m.name, m.name.empty() ? "" : "'");
    if (m.name.empty()) return absl::InvalidArgumentError(where + ": name is empty");
    if (!std::isfinite(m.min) || !std::isfinite(m.max) || !(m.min < m.max)) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": interval [", m.min, ", ", m.max, ") is empty or not finite"));
    }
    if (auto s = CheckColor(where, m.color.data(), 3); !s.ok()) return s;
    if (!InUnit(m.opacity)) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": opacity ", m.opacity, " is not in [0, 1]"));
    }
    if (auto s = CheckPhong(where, m.ambient, m.diffuse, m.specular, m.shininess); !s.ok()) {
      return s;
    }
  }
  return absl::OkStatus();
}

const char* SurfaceModelName(SurfaceModel model) {
  return model == SurfaceModel::kVoxel ? "voxel" : "smooth";
}

Bands::Bands(const Classification& classification) {
  for (const Material& m : classification.materials) {
    edges_.push_back(m.min);
    edges_.push_back(m.max);
  }
  std::sort(edges_.begin(), edges_.end());
  edges_.erase(std::unique(edges_.begin(), edges_.end()), edges_.end());
  // Band 0 lies below every edge, where no interval reaches; band i >= 1
  // starts at edge i - 1, which it holds.
  materials_.push_back(0);
  for (float e : edges_) materials_.push_back(classification.Classify(e));
}

int Bands::Of(float value) const {
  if (!(value == value)) return 0;
  return static_cast<int>(std::upper_bound(edges_.begin(), edges_.end(), value) - edges_.begin());
}

absl::Status TransferFunction::Validate() const {
  if (points.size() < 2) {
    return absl::InvalidArgumentError(
        absl::StrCat("transfer function: ", points.size(), " points given, need at least 2"));
  }
  for (size_t i = 0; i < points.size(); ++i) {
    std::string where = absl::StrCat("transfer function point ", i);
    if (!std::isfinite(points[i].value)) {
      return absl::InvalidArgumentError(where + ": value is not finite");
    }
    if (i > 0 && !(points[i].value > points[i - 1].value)) {
      return absl::InvalidArgumentError(absl::StrCat(
          where, ": value ", points[i].value, " does not increase on ", points[i - 1].value));
    }
    if (auto s = CheckColor(where, points[i].rgba.data(), 4); !s.ok()) return s;
  }
  if (!std::isfinite(reference_step) || reference_step <= 0) {
    return absl::InvalidArgumentError("transfer function: reference_step must be positive");
  }
  return CheckPhong("transfer function", ambient, diffuse, specular, shininess);
}

std::array<float, 4> TransferFunction::Evaluate(float value) const {
  if (points.empty()) return {0, 0, 0, 0};
  if (value <= points.front().value) return points.front().rgba;
  if (value >= points.back().value) return points.back().rgba;
  size_t i = 1;
  while (points[i].value < value) ++i;
  const TransferPoint& a = points[i - 1];
  const TransferPoint& b = points[i];
  // Points more than FLT_MAX apart (b.value - a.value overflows, and
  // value - a.value may too: inf / inf is NaN) are interpolated in double.
  const float f = std::isfinite(b.value - a.value)
                      ? (value - a.value) / (b.value - a.value)
                      : static_cast<float>((double{value} - a.value) / (double{b.value} - a.value));
  std::array<float, 4> out;
  for (int c = 0; c < 4; ++c) out[c] = a.rgba[c] + f * (b.rgba[c] - a.rgba[c]);
  return out;
}

namespace {

std::string RangeText(const std::array<float, 2>& range) {
  return absl::StrCat("the volume's values are ", range[0], " .. ", range[1]);
}

}  // namespace

std::vector<std::string> UnseenMaterials(const Classification& classification,
                                         const Volume& volume) {
  std::vector<std::string> out;
  const std::array<float, 2> range = volume.Range();
  std::vector<uint64_t> voxels;
  if (classification.surface == SurfaceModel::kVoxel) {
    voxels.assign(classification.materials.size() + 1, 0);
    for (float v : volume.values) ++voxels[classification.Classify(v)];
  }
  for (size_t i = 0; i < classification.materials.size(); ++i) {
    const Material& m = classification.materials[i];
    const bool misses = m.max <= range[0] || m.min > range[1];
    if (classification.surface == SurfaceModel::kSmooth && misses) {
      out.push_back(absl::StrCat("material '", m.name, "' [", m.min, ", ", m.max,
                                 ") shows nothing: ", RangeText(range)));
    } else if (classification.surface == SurfaceModel::kVoxel && voxels[i + 1] == 0) {
      out.push_back(absl::StrCat("material '", m.name, "' [", m.min, ", ", m.max,
                                 ") covers no voxel: ", RangeText(range),
                                 misses ? "" : ", and an earlier material takes those in it"));
    }
  }
  return out;
}

std::vector<std::string> UnseenTransfer(const TransferFunction& transfer, const Volume& volume) {
  const std::array<float, 2> range = volume.Range();
  // Piecewise linear: the largest opacity over the range is at its ends or
  // at a point inside it.
  float alpha = std::max(transfer.Evaluate(range[0])[3], transfer.Evaluate(range[1])[3]);
  for (const TransferPoint& p : transfer.points) {
    if (p.value > range[0] && p.value < range[1]) alpha = std::max(alpha, p.rgba[3]);
  }
  if (alpha > 0) return {};
  return {absl::StrCat("the transfer function is transparent over the whole volume (",
                       RangeText(range), "): the image will be the background")};
}

}  // namespace transtick

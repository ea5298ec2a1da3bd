#include "transtick/presets.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"

namespace transtick {
namespace {

struct PresetMaterial {
  const char* name;
  float min, max;
  std::array<float, 3> color;
  float opacity;
};

struct Preset {
  const char* name;
  const char* description;
  bool relative;
  std::vector<PresetMaterial> materials;
  std::vector<TransferPoint> transfer;
};

// Colours and thresholds after ParaView's CT-Bone, CT-Muscle, CT-AAA and
// MR-Default presets and the usual Hounsfield ranges: fat about -100, soft
// tissue 20..80, contrast-filled vessels 150..500, bone above 300.
const std::vector<Preset>& Presets() {
  static const auto* kPresets = new std::vector<Preset>{
      {"ct-bone", "CT (Hounsfield units): bone", false,
       {{"bone", 300, 4000, {0.96f, 0.94f, 0.86f}, 1.0f}},
       {{150, {0.55f, 0.25f, 0.15f, 0}},
        {300, {0.9f, 0.82f, 0.56f, 0.15f}},
        {1200, {1, 1, 0.9f, 0.6f}},
        {3000, {1, 1, 1, 0.8f}}}},
      {"ct-skin-bone", "CT (Hounsfield units): skin at 30% over bone", false,
       {{"skin", -300, 300, {0.92f, 0.72f, 0.6f}, 0.3f},
        {"bone", 300, 4000, {0.96f, 0.94f, 0.86f}, 1.0f}},
       {{-500, {0, 0, 0, 0}},
        {-300, {0.74f, 0.5f, 0.4f, 0.02f}},
        {100, {0.85f, 0.6f, 0.5f, 0.03f}},
        {300, {0.9f, 0.82f, 0.56f, 0.2f}},
        {1200, {1, 1, 0.9f, 0.7f}}}},
      {"ct-angio", "CT angiography (Hounsfield units): contrast-filled vessels, bone faint", false,
       {{"vessels", 150, 500, {0.85f, 0.15f, 0.12f}, 1.0f},
        {"bone", 500, 4000, {0.96f, 0.94f, 0.86f}, 0.25f}},
       {{100, {0, 0, 0, 0}},
        {150, {0.7f, 0.1f, 0.08f, 0.2f}},
        {450, {1, 0.4f, 0.3f, 0.6f}},
        {500, {0.9f, 0.9f, 0.85f, 0.05f}},
        {2000, {1, 1, 1, 0.1f}}}},
      {"mr-brain", "MR (relative to the value range): head at 15% over brain", true,
       {{"head", 0.12f, 0.3f, {0.92f, 0.72f, 0.6f}, 0.15f},
        {"brain", 0.3f, 1.01f, {0.9f, 0.75f, 0.72f}, 1.0f}},
       {{0.08f, {0, 0, 0, 0}},
        {0.2f, {0.6f, 0.45f, 0.4f, 0.02f}},
        {0.35f, {0.85f, 0.7f, 0.65f, 0.15f}},
        {1.0f, {1, 0.95f, 0.9f, 0.5f}}}},
      {"grey", "colormap (relative): black to white, opacity rising with the value", true,
       {},
       {{0, {0, 0, 0, 0}}, {1, {1, 1, 1, 0.5f}}}},
      {"hot", "colormap (relative): black, red, yellow, white, opacity rising", true,
       {},
       {{0, {0, 0, 0, 0}},
        {0.35f, {0.9f, 0, 0, 0.1f}},
        {0.7f, {1, 0.85f, 0, 0.3f}},
        {1, {1, 1, 1, 0.5f}}}},
      {"cool-warm", "colormap (relative): ParaView's diverging blue to red, opacity rising", true,
       {},
       {{0, {0.23f, 0.3f, 0.75f, 0}},
        {0.5f, {0.87f, 0.87f, 0.87f, 0.15f}},
        {1, {0.71f, 0.02f, 0.15f, 0.5f}}}},
  };
  return *kPresets;
}

absl::StatusOr<const Preset*> Find(std::string_view name) {
  for (const Preset& p : Presets()) {
    if (name == p.name) return &p;
  }
  std::vector<std::string> names;
  for (const Preset& p : Presets()) names.push_back(p.name);
  return absl::NotFoundError(absl::StrCat("unknown preset '", std::string(name), "' (presets: ",
                                          absl::StrJoin(names, ", "), ")"));
}

// A relative value in the volume's range [lo, hi] (a range of one value is
// widened to one unit, so that the points still increase).
float Scale(const Preset& p, float v, const std::array<float, 2>& range) {
  if (!p.relative) return v;
  const float lo = range[0];
  const float width = range[1] > range[0] ? range[1] - range[0] : 1.0f;
  return lo + v * width;
}

}  // namespace

std::vector<PresetInfo> ListPresets() {
  std::vector<PresetInfo> out;
  for (const Preset& p : Presets()) {
    out.push_back({p.name, p.description, !p.materials.empty(), !p.transfer.empty(), p.relative});
  }
  return out;
}

absl::StatusOr<Classification> PresetMaterials(std::string_view name,
                                               const std::array<float, 2>& range) {
  auto p = Find(name);
  if (!p.ok()) return p.status();
  if ((*p)->materials.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat("preset '", std::string(name), "' is a colormap for dvr mode; it has no surfaces"));
  }
  Classification c;
  for (const PresetMaterial& m : (*p)->materials) {
    Material material;
    material.name = m.name;
    material.min = Scale(**p, m.min, range);
    material.max = Scale(**p, m.max, range);
    material.color = m.color;
    material.opacity = m.opacity;
    c.materials.push_back(material);
  }
  if (absl::Status s = c.Validate(); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("preset '", std::string(name), "': ", s.message()));
  }
  return c;
}

absl::StatusOr<TransferFunction> PresetTransfer(std::string_view name,
                                                const std::array<float, 2>& range) {
  auto p = Find(name);
  if (!p.ok()) return p.status();
  TransferFunction tf;
  for (TransferPoint point : (*p)->transfer) {
    point.value = Scale(**p, point.value, range);
    // A narrow range may round two relative points together.
    if (!tf.points.empty() && !(point.value > tf.points.back().value)) continue;
    tf.points.push_back(point);
  }
  if (tf.points.size() == 1) {
    TransferPoint end = tf.points.back();
    end.value = std::nextafter(end.value, HUGE_VALF);
    tf.points.push_back(end);
  }
  if (absl::Status s = tf.Validate(); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("preset '", std::string(name), "': ", s.message()));
  }
  return tf;
}

}  // namespace transtick

// Classification: scalar values to materials (surfaces mode) and to colour and
// opacity through a transfer function (dvr mode).
#ifndef TRANSTICK_CLASSIFICATION_H_
#define TRANSTICK_CLASSIFICATION_H_

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"

namespace transtick {

// One threshold surface of the paper: the voxels whose value lies in
// [min, max) belong to this material. Shading follows Phong: ambient +
// diffuse * max(N.L, 0) * color + specular * max(N.H, 0)^shininess.
struct Material {
  std::string name;
  float min = 0;
  float max = 0;
  std::array<float, 3> color = {1, 1, 1};
  float opacity = 1;  // fraction of light stopped at the surface, in [0, 1]
  float ambient = 0.25f;
  float diffuse = 0.7f;
  float specular = 0.25f;
  float shininess = 24.0f;
};

// Where a material's surface lies (docs/design.md, "Smooth surfaces").
enum class SurfaceModel : uint8_t {
  // The isosurface of the trilinear field at the interval's edges, hit
  // exactly: the default.
  kSmooth,
  // The paper's: the faces of the voxels whose value lies in the interval.
  kVoxel,
};
// "smooth" or "voxel".
const char* SurfaceModelName(SurfaceModel model);

// Material id 0 is void; material i (1-based) is materials[i - 1]. When
// intervals overlap, the first listed wins. Immutable after Validate():
// thread-safe for concurrent reads.
struct Classification {
  // 255 marks mixed bricks.
  static constexpr int kMaxMaterials = 254;
  std::vector<Material> materials;
  SurfaceModel surface = SurfaceModel::kSmooth;

  // The largest label a voxel of this classification's sticks may carry.
  int MaxLabel() const { return static_cast<int>(materials.size()); }

  // Checks intervals (min < max, finite), colours and coefficients in range,
  // opacity in [0, 1], at most kMaxMaterials, names non-empty.
  absl::Status Validate() const;

  uint8_t Classify(float value) const {
    for (size_t i = 0; i < materials.size(); ++i) {
      if (value >= materials[i].min && value < materials[i].max) return static_cast<uint8_t>(i + 1);
    }
    return 0;
  }
};

// The value line cut at every interval edge of a classification: band i
// holds the values v with exactly i edges <= v, so band 0 is (-inf, e_0),
// band i is [e_(i-1), e_i) and the last is [e_last, inf). Classify is
// constant on a band; a ray moving through the field changes band exactly
// where the field crosses an edge. Immutable, thread-safe.
class Bands {
 public:
  Bands() = default;
  explicit Bands(const Classification& classification);

  int Of(float value) const;  // NaN gives band 0
  int size() const { return static_cast<int>(materials_.size()); }
  uint8_t material(int band) const { return materials_[band]; }
  const std::vector<float>& edges() const { return edges_; }
  // The band a crossing of edge i enters: i + 1 going up, i going down.
  static int Above(int edge) { return edge + 1; }
  static int Below(int edge) { return edge; }

 private:
  std::vector<float> edges_;       // sorted, distinct
  std::vector<uint8_t> materials_;  // by band
};

// A piecewise-linear map from scalar value to RGBA. Opacity is per unit of
// `TransferFunction::reference_step` (world units): a sample taken with step s
// gets alpha' = 1 - (1 - alpha)^(s / reference_step). Below the first point
// and above the last, the end values hold.
struct TransferPoint {
  float value = 0;
  std::array<float, 4> rgba = {0, 0, 0, 0};
};

struct TransferFunction {
  std::vector<TransferPoint> points;  // strictly increasing values
  float reference_step = 1.0f;
  // Lighting applied to samples when `shading` is set (dvr mode).
  bool shading = true;
  float ambient = 0.3f;
  float diffuse = 0.7f;
  float specular = 0.2f;
  float shininess = 20.0f;

  // Checks at least 2 points with finite, strictly increasing values and
  // RGBA in [0, 1], a positive reference_step, and the shading coefficients
  // as a material's (ambient, diffuse, specular in [0, 4], shininess in
  // [1, 1000]).
  absl::Status Validate() const;
  std::array<float, 4> Evaluate(float value) const;
};

struct Volume;

// What a user should be told before a render: one sentence for each
// material no ray can meet in `volume`, naming it and the volume's range of
// values. A smooth surface lies where the trilinear field crosses the
// interval's edges, and the field takes every value between the volume's
// smallest and largest sample, so a smooth material is unseen when its
// interval misses that range; a voxel material is unseen when no voxel
// classifies as it (an earlier, overlapping interval may take them all).
// Empty when every material can be seen.
std::vector<std::string> UnseenMaterials(const Classification& classification,
                                         const Volume& volume);

// The same for a transfer function: a sentence when its opacity is zero over
// the whole range of `volume`'s values, so the image is the background.
std::vector<std::string> UnseenTransfer(const TransferFunction& transfer, const Volume& volume);

}  // namespace transtick

#endif  // TRANSTICK_CLASSIFICATION_H_

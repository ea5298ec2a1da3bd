#include "batch_setup.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>

#include "transtick/synthetic.h"

namespace transtick::fuzz {
namespace {

Scene MakeSurfaces() {
  Volume v = MakeNoisyPhantom({24, 20, 16}, 3);
  v.spacing = {1, 1, 1.5};
  Classification c;
  c.materials = {{.name = "soft", .min = 20, .max = 45, .opacity = 0.3f},
                 {.name = "hard", .min = 45, .max = 1000, .opacity = 1.0f}};
  auto scene = Scene::ForSurfaces(v, c);
  if (!scene.ok()) std::abort();
  return *std::move(scene);
}

Scene MakeDvr() {
  Volume v = MakeNoisyPhantom({20, 20, 14}, 4);
  v.spacing = {0.8, 1.25, 1};
  TransferFunction tf;
  tf.points = {{10, {0, 0, 0, 0}}, {40, {1, 0.6f, 0.3f, 0.2f}}, {90, {1, 1, 1, 0.9f}}};
  auto scene = Scene::ForDvr(v, tf);
  if (!scene.ok()) std::abort();
  return *std::move(scene);
}

Camera MakeCamera(const Scene& scene, bool second_view) {
  CameraSpec spec;
  if (second_view) {
    spec.azimuth_deg = 200;
    spec.elevation_deg = -35;
    spec.projection = Projection::kOrthographic;
    spec.width = 17;
    spec.height = 13;
  } else {
    spec.azimuth_deg = 30;
    spec.elevation_deg = 10;
    spec.width = spec.height = 24;
  }
  const auto& d = scene.dims();
  const auto& sp = scene.spacing();
  auto camera = Camera::Create(spec, Vec3{d[0] * sp[0], d[1] * sp[1], d[2] * sp[2]});
  if (!camera.ok()) std::abort();
  return *std::move(camera);
}

}  // namespace

BatchSetup& BatchSetup::Get() {
  static BatchSetup* setup = new BatchSetup();
  return *setup;
}

BatchSetup::BatchSetup() : surfaces_(MakeSurfaces()), dvr_(MakeDvr()) {
  configs_.reserve(kBatchConfigs);
  for (int i = 0; i < kBatchConfigs; ++i) {
    const bool dvr = (i & 1) != 0;
    const bool slabs = (i & 2) != 0;
    const bool second_view = (i & 4) != 0;
    const Scene& scene = dvr ? dvr_ : surfaces_;
    const int ny = scene.dims()[1];
    // Surfaces cut with a slab one plane thick, which rays cross in one
    // segment or skip.
    std::vector<int> cuts = {0, ny};
    if (slabs) cuts = dvr ? std::vector<int>{0, 10, ny} : std::vector<int>{0, 7, 8, ny};
    RenderSettings settings;
    settings.shadows = !second_view;
    if (dvr && second_view) settings.step = 0.3;
    Camera camera = MakeCamera(scene, second_view);
    auto ring = std::make_unique<FuzzRing>(scene, cuts, camera, settings);
    configs_.push_back({&scene, camera, settings, std::move(ring)});
  }
}

void Repair(const Scene& scene, const Tracer& tracer, RayDescriptor* r) {
  const auto& sp = scene.spacing();
  const auto& d = scene.dims();
  const Vec3 world{r->direction.x * sp[0], r->direction.y * sp[1], r->direction.z * sp[2]};
  const double length = Length(world);
  if (!(length > 0) || !std::isfinite(length)) return;
  for (int a = 0; a < 3; ++a) r->direction[a] = world[a] / length / sp[a];
  if (!std::isfinite(r->t) || !std::isfinite(r->t_start)) return;
  const double diagonal = Length(Vec3{d[0] * sp[0], d[1] * sp[1], d[2] * sp[2]});
  r->t = std::fmod(std::fabs(r->t), 2 * diagonal);
  if (!(r->t_start <= r->t && r->t - r->t_start <= diagonal)) {
    r->t_start = r->t - std::fmod(std::fabs(r->t - r->t_start), diagonal);
  }
  // A point inside the volume taken from the origin's bits, and the origin
  // moved so that the ray is there at t.
  Vec3 q;
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(r->origin[a])) return;
    q[a] = std::fmod(std::fabs(r->origin[a]), static_cast<double>(d[a]));
    r->cell[a] = std::clamp(static_cast<int32_t>(std::floor(q[a])), 0, d[a] - 1);
  }
  r->origin = q - r->direction * r->t;
  const size_t materials = scene.classification().materials.size();
  r->material = static_cast<uint8_t>(r->material % (materials + 1));
  if (scene.mode() == RenderMode::kDvr) {
    r->sample = std::min<uint32_t>(
        r->sample, static_cast<uint32_t>(std::floor((r->t - r->t_start) / tracer.step())));
  }
  for (float& c : r->color) {
    if (!std::isfinite(c)) c = 0;
  }
  if (!(r->transmittance >= 0 && r->transmittance <= 1)) {
    r->transmittance =
        std::isfinite(r->transmittance) ? std::fmod(std::fabs(r->transmittance), 1.0f) : 1.0f;
  }
}

}  // namespace transtick::fuzz

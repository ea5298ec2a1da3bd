#include "transtick/tracer.h"

#include <algorithm>
#include <cmath>
#include <limits>

#if defined(__SSE2__)
#include <immintrin.h>
#endif

#include "absl/strings/str_cat.h"
#include "transtick/isosurface.h"
#include "transtick/traversal.h"

namespace transtick {
namespace {

Vec3f ToFloat(const Vec3& v) {
  return {static_cast<float>(v.x), static_cast<float>(v.y), static_cast<float>(v.z)};
}

// Keeps a point computed from t inside the cell it belongs to, so rounding
// can never send a gradient or sample outside the planes a slab holds.
Vec3 ClampToCell(Vec3 p, const std::array<int32_t, 3>& cell) {
  for (int a = 0; a < 3; ++a) p[a] = std::clamp(p[a], double(cell[a]), double(cell[a] + 1));
  return p;
}

// Far-away numbers would lose the cell in rounding (and overflow the
// traversal's integer cells): Validate refuses origins beyond this, and t
// beyond it times the largest spacing (t is in world units).
constexpr double kFar = 1e9;
// A primary ray whose origin or entry lies beyond this starts at its entry.
constexpr double kRebase = kFar / 1000;

}  // namespace

absl::Status CheckRenderSettings(const RenderSettings& settings, RenderMode mode,
                                 const std::array<int, 3>& dims,
                                 const std::array<double, 3>& spacing, int64_t pixels) {
  if (settings.samples < 1 || settings.samples > kMaxSamplesPerPixel) {
    return absl::InvalidArgumentError(absl::StrCat("samples ", settings.samples,
                                                   " must be in [1, ", kMaxSamplesPerPixel, "]"));
  }
  if (mode != RenderMode::kDvr) return absl::OkStatus();
  pixels *= settings.samples;
  const double min_spacing = std::min({spacing[0], spacing[1], spacing[2]});
  if (!std::isfinite(settings.step) || settings.step < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "step ", settings.step, " must be a finite positive number (or 0 for the default)"));
  }
  const double least = min_spacing / kMaxSamplesPerVoxel;
  if (settings.step > 0 && settings.step < least) {
    return absl::InvalidArgumentError(
        absl::StrCat("step ", settings.step, " is finer than the finest allowed, ", least, " (1/",
                     kMaxSamplesPerVoxel, " of the smallest voxel spacing, ", min_spacing, ")"));
  }
  const double step = settings.step > 0 ? settings.step : 0.5 * min_spacing;
  const double diagonal =
      Length(Vec3{dims[0] * spacing[0], dims[1] * spacing[1], dims[2] * spacing[2]});
  const double samples = static_cast<double>(pixels) * std::ceil(diagonal / step);
  if (samples > kMaxFrameSamples) {
    return absl::InvalidArgumentError(
        absl::StrCat("a frame of ", pixels, " pixels at step ", step, " may take ", samples,
                     " samples, more than the limit of ", kMaxFrameSamples,
                     "; use a coarser step or a smaller image"));
  }
  return absl::OkStatus();
}

Tracer::Tracer(const Scene& scene, const RenderSettings& settings, const Camera& camera)
    : scene_(scene), settings_(settings) {
  const auto& sp = scene.spacing();
  inv_spacing_ = {1.0 / sp[0], 1.0 / sp[1], 1.0 / sp[2]};
  Vec3 l = camera.right() * settings.light.x + camera.up() * settings.light.y -
           camera.forward() * settings.light.z;
  light_world_ = Normalize(l);
  if (Length(light_world_) == 0) light_world_ = -camera.forward();
  light_index_ = light_world_ * inv_spacing_;
  smooth_ = scene.mode() == RenderMode::kSurfaces &&
            scene.classification().surface == SurfaceModel::kSmooth;
  if (smooth_) {
    bands_ = Bands(scene.classification());
    if (bands_.material(0) == 0) meets_ = scene.summary().PixelsMeeting(camera, sp);
  }
  work_ = smooth_ ? &kFieldWork : &kTraversalWork;
  shadow_bias_ = 1.5 / Length(light_index_);
  const double min_spacing = std::min({sp[0], sp[1], sp[2]});
  // A step below the bound (CheckRenderSettings refuses it) is raised to it
  // here too, so that no caller can make a ray take unbounded samples.
  step_ = settings.step > 0 && std::isfinite(settings.step) ? settings.step : 0.5 * min_spacing;
  step_ = std::max(step_, min_spacing / kMaxSamplesPerVoxel);
  const auto& d = scene.dims();
  diagonal_ = Length(Vec3{d[0] * sp[0], d[1] * sp[1], d[2] * sp[2]});
  max_segments_ = Traversal::MaxSegments(d) + 1;
  // Sample positions from the ray's entry to its exit, plus the one past
  // the end that each segment looks at. Spacings many orders of magnitude
  // apart (a file may say so) make that count overflow an integer; no frame
  // may take more than kMaxFrameSamples (CheckRenderSettings), so no ray
  // needs more either.
  const double span = std::ceil(diagonal_ / step_);
  max_samples_ =
      static_cast<int64_t>(span <= kMaxFrameSamples ? span : kMaxFrameSamples) + 2 + max_segments_;
  if (scene.mode() == RenderMode::kDvr) {
    const TransferFunction& tf = scene.transfer();
    const float lo = scene.value_range()[0], hi = scene.value_range()[1];
    table_.resize(kTableSize);
    table_lo_ = lo;
    // A range wider than a float holds (values near +-FLT_MAX: hi - lo
    // overflows) is spanned in double; in float the table came out NaN.
    const bool wide = !std::isfinite(hi - lo);
    const double wide_span = static_cast<double>(hi) - lo;
    table_scale_ = !(hi > lo) ? 0.0f
                   : wide     ? static_cast<float>((kTableSize - 1) / wide_span)
                              : (kTableSize - 1) / (hi - lo);
    const double exponent = step_ / tf.reference_step;
    for (int i = 0; i < kTableSize; ++i) {
      float v = !(hi > lo) ? lo
                : wide     ? static_cast<float>(lo + i * wide_span / (kTableSize - 1))
                           : lo + i * (hi - lo) / (kTableSize - 1);
      auto rgba = tf.Evaluate(v);
      float a = static_cast<float>(1.0 - std::pow(1.0 - rgba[3], exponent));
      table_[i] = {{rgba[0], rgba[1], rgba[2]}, a};
    }
  }
}

bool Tracer::MakePrimary(const WorldRay& world, uint32_t pixel, RayDescriptor* ray) const {
  const auto& dims = scene_.dims();
  Vec3 half{dims[0] * 0.5, dims[1] * 0.5, dims[2] * 0.5};
  Vec3 o = world.origin * inv_spacing_ + half;
  Vec3 d = world.direction * inv_spacing_;
  auto box = IntersectBox(o, d, dims);
  if (!box) return false;
  double t = (*box)[0];
  // An eye far from the volume (an explicit view may put it anywhere, and a
  // tiny spacing puts it far in index space) gives an origin or t that a
  // neighbour's Validate refuses, so every ray handed on was dropped and the
  // frame aborted (found by job_fuzzer and volume_fuzzer). Such a ray starts
  // where it enters instead: the same line, t counted from there. Ordinary
  // views keep their origin, bit for bit.
  if (!(std::abs(t) <= kRebase && std::abs(o.x) <= kRebase && std::abs(o.y) <= kRebase &&
        std::abs(o.z) <= kRebase)) {
    o = o + d * t;
    t = 0;
  }
  *ray = RayDescriptor{};
  ray->origin = o;
  ray->direction = d;
  ray->t = t;
  ray->t_start = t;
  ray->cell = CellAt(o, d, ray->t, dims);
  ray->pixel = pixel;
  ray->kind = RayKind::kPrimary;
  return true;
}

absl::Status Tracer::Validate(const RayDescriptor& r) const {
  auto bad = [](auto&&... what) { return absl::InvalidArgumentError(absl::StrCat(what...)); };
  bool finite = std::isfinite(r.t) && std::isfinite(r.t_start) && std::isfinite(r.transmittance);
  for (int a = 0; a < 3; ++a) {
    finite = finite && std::isfinite(r.origin[a]) && std::isfinite(r.direction[a]) &&
             std::isfinite(r.color[a]);
  }
  if (!finite) return bad("non-finite origin, direction, t, colour or transmittance");
  // The origin is in voxels; t is a distance in world units, so a voxel of
  // spacing s is s units of t (with a huge spacing a ray's t passes kFar
  // within a voxel of its entry: found by volume_fuzzer).
  const auto& spacing = scene_.spacing();
  const double far_t = kFar * std::max({1.0, spacing[0], spacing[1], spacing[2]});
  if (!(std::abs(r.t) <= far_t && std::abs(r.t_start) <= far_t && std::abs(r.origin.x) <= kFar &&
        std::abs(r.origin.y) <= kFar && std::abs(r.origin.z) <= kFar)) {
    return bad("origin further than ", kFar, " voxels or t further than ", kFar,
               " voxels' spacing from the volume");
  }
  if (r.kind != RayKind::kPrimary && r.kind != RayKind::kShadow) {
    return bad("unknown kind ", static_cast<int>(r.kind));
  }
  // Only surfaces with shadows spawn shadow rays; a dvr scene has no
  // materials for one to cross.
  if (r.kind == RayKind::kShadow &&
      (scene_.mode() != RenderMode::kSurfaces || !settings_.shadows)) {
    return bad("a shadow ray, but this frame ",
               scene_.mode() == RenderMode::kDvr ? "is dvr" : "has shadows off");
  }
  // The world direction, direction * spacing, is a unit vector.
  const auto& sp = scene_.spacing();
  const double length =
      Length(Vec3{r.direction.x * sp[0], r.direction.y * sp[1], r.direction.z * sp[2]});
  if (!(std::abs(length - 1) <= 1e-6)) {
    return bad("world direction of length ", length, ", not 1");
  }
  const auto& dims = scene_.dims();
  if (!Traversal::Inside(r.cell, dims)) {
    return bad("cell (", r.cell[0], ", ", r.cell[1], ", ", r.cell[2], ") outside the ", dims[0],
               "x", dims[1], "x", dims[2], " volume");
  }
  // The cell and the point at t agree, give or take a cell for rounding at
  // faces (traversal clamps a coordinate to its box and never moves it back).
  const Vec3 p = r.origin + r.direction * r.t;
  for (int a = 0; a < 3; ++a) {
    if (!(p[a] >= r.cell[a] - 1.0 && p[a] <= r.cell[a] + 2.0)) {
      return bad("cell (", r.cell[0], ", ", r.cell[1], ", ", r.cell[2],
                 ") is not where the ray is at t = ", r.t, " (", p.x, ", ", p.y, ", ", p.z, ")");
    }
  }
  if (!(r.t >= 0 && r.t_start <= r.t && r.t - r.t_start <= diagonal_ * (1 + 1e-9) + 1e-6)) {
    return bad("t = ", r.t, " and t_start = ", r.t_start,
               " do not lie on one pass through the volume");
  }
  if (scene_.mode() == RenderMode::kDvr && !(r.sample <= (r.t - r.t_start) / step_ + 2)) {
    return bad("sample index ", r.sample, " is past the ray's position");
  }
  const size_t materials = scene_.classification().materials.size();
  if (scene_.mode() == RenderMode::kSurfaces && r.material > materials) {
    return bad("material ", int{r.material}, " of ", materials);
  }
  if (r.band != RayDescriptor::kNoBand && (!smooth_ || r.band >= bands_.size())) {
    return bad("band ", r.band, smooth_ ? absl::StrCat(" of ", bands_.size()) : " without smooth surfaces");
  }
  if (!(r.transmittance >= 0 && r.transmittance <= 1)) {
    return bad("transmittance ", r.transmittance, " outside [0, 1]");
  }
  return absl::OkStatus();
}

Deposit Tracer::MissDeposit(uint32_t pixel) const {
  return Deposit{pixel, RayKind::kPrimary, 0, settings_.background};
}

Tracer::Outcome Tracer::Trace(RayDescriptor& ray, std::vector<RayDescriptor>& spawned,
                              Deposit& deposit, TraceCounters& counters) const {
  if (counters.plane_work && ray.cell[1] >= scene_.y_begin() && ray.cell[1] < scene_.y_end()) {
    counters.plane_work[ray.cell[1] - scene_.y_begin()] += work_->ray;
  }
  Outcome outcome;
  if (smooth_) {
    outcome = TraceSmooth(ray, spawned, counters);
  } else if (ray.kind == RayKind::kShadow) {
    outcome = TraceShadow(ray, counters);
  } else if (scene_.mode() == RenderMode::kSurfaces) {
    outcome = TraceSurfaces(ray, spawned, counters);
  } else {
    outcome = TraceDvr(ray, counters);
  }
  if (outcome == Outcome::kFinished) {
    deposit.pixel = ray.pixel;
    deposit.kind = ray.kind;
    if (ray.kind == RayKind::kPrimary) {
      deposit.spawned = ray.spawned;
      for (int c = 0; c < 3; ++c)
        deposit.color[c] = ray.color[c] + ray.transmittance * settings_.background[c];
    } else {
      deposit.spawned = 0;
      for (int c = 0; c < 3; ++c) deposit.color[c] = ray.color[c] * ray.transmittance;
    }
  }
  return outcome;
}

TRANSTICK_INLINE std::optional<Tracer::Step> Tracer::Walk(Walker& w, Outcome* outcome,
                                                          TraceCounters& counters) {
  // Element by element: copied whole, the cell is read in one 8-byte load
  // of two 4-byte stores the last step made, which the CPU cannot forward
  // (measured: the cthead bench 18% slower).
  const std::array<int32_t, 3> cell = {w.trav.cell()[0], w.trav.cell()[1], w.trav.cell()[2]};
  if (!Traversal::Inside(cell, w.dims)) {
    *outcome = Outcome::kFinished;
    return std::nullopt;
  }
  // The slab holds the cell's plane, or the ray goes on elsewhere (where:
  // RingLayout::Route).
  if (cell[1] < w.y_begin || cell[1] >= w.y_end) {
    *outcome = Outcome::kLeftSlab;
    return std::nullopt;
  }
  std::optional<Segment> seg;
  if (--w.steps_left < 0 || !(seg = w.trav.NextInside())) {
    ++counters.truncated;
    *outcome = Outcome::kFinished;
    return std::nullopt;
  }
  ++counters.segments;
  if (counters.plane_work) counters.plane_work[cell[1] - w.y_begin] += w.step_work;
  return Step{*seg, cell};
}

bool Tracer::Shade(RayDescriptor& ray, uint8_t m, const Vec3& p, const Vec3& view,
                   const std::array<int32_t, 3>& shadow_cell, double shadow_t,
                   uint16_t shadow_band, uint8_t shadow_material,
                   std::vector<RayDescriptor>& spawned, TraceCounters& counters) const {
  ++counters.surface_hits;
  if (counters.plane_work) {
    counters.plane_work[FloorClamped(p.y, scene_.y_begin(), scene_.y_end() - 1) -
                        scene_.y_begin()] += work_->hit;
  }
  const Material& mat = scene_.classification().materials[m - 1];
  float diffuse, specular;
  Light(Gradient(p), view, &diffuse, &specular, mat.shininess);
  const float w = ray.transmittance * mat.opacity;
  std::array<float, 3> direct;
  for (int c = 0; c < 3; ++c) {
    ray.color[c] += w * mat.ambient * mat.color[c];
    direct[c] = w * (mat.diffuse * diffuse * mat.color[c] + mat.specular * specular);
  }
  const bool lit = direct[0] > 0 || direct[1] > 0 || direct[2] > 0;
  if (lit && settings_.shadows && ray.spawned < UINT16_MAX) {
    RayDescriptor s;
    s.origin = p;
    s.direction = light_index_;
    s.t = shadow_t;
    s.t_start = 0;
    s.cell = shadow_cell;
    s.pixel = ray.pixel;
    s.kind = RayKind::kShadow;
    s.material = shadow_material;
    s.band = shadow_band;
    s.color = direct;
    s.transmittance = 1;
    spawned.push_back(s);
    ++ray.spawned;
    ++counters.shadow;
  } else if (lit) {
    for (int c = 0; c < 3; ++c) ray.color[c] += direct[c];
  }
  ray.transmittance *= 1.0f - mat.opacity;
  return ray.transmittance < settings_.min_transmittance;
}

Tracer::Outcome Tracer::TraceSmooth(RayDescriptor& ray, std::vector<RayDescriptor>& spawned,
                                    TraceCounters& counters) const {
  const int y_begin = scene_.y_begin(), y_end = scene_.y_end();
  // A ray whose plane another slab holds goes on there (RingLayout::Route),
  // as Walk sends it.
  if (ray.cell[1] < y_begin || ray.cell[1] >= y_end) return Outcome::kLeftSlab;
  const auto& dims = scene_.dims();
  const RayAxes axes(ray.direction);
  // The ray's part here: from t to where it leaves the volume, or the slab
  // before that (each time from its plane).
  double t_volume = std::numeric_limits<double>::infinity();
  double t_slab = t_volume;
  for (int a = 0; a < 3; ++a) {
    if (axes.step[a] == 0) continue;
    t_volume = std::min(t_volume, ((axes.step[a] > 0 ? dims[a] : 0) - ray.origin[a]) * axes.inv[a]);
  }
  if (axes.step[1] > 0 && y_end < dims[1]) {
    t_slab = (y_end - ray.origin.y) * axes.inv[1];
  } else if (axes.step[1] < 0 && y_begin > 0) {
    t_slab = (y_begin - ray.origin.y) * axes.inv[1];
  }
  const bool leaves_slab = t_slab < t_volume;
  const double end = std::max(std::min(t_volume, t_slab), ray.t);
  WalkWork work;
  if (counters.plane_work) work = {counters.plane_work, y_begin, y_end, work_->step, work_->cell};
  CrossingWalk walk(scene_, bands_, ray.origin, axes, ray.t, end,
                    ray.band == RayDescriptor::kNoBand ? -1 : ray.band, work);
  // Only a shaded crossing's time is asked: a root's refinement is left
  // out where the ray enters no material, and for every shadow ray.
  walk.DeferTimes();
  const bool primary = ray.kind == RayKind::kPrimary;
  std::optional<Vec3> view;  // toward the eye, made at the first hit (divisions and a root)
  const auto& materials = scene_.classification().materials;
  bool finished = false;
  while (auto c = walk.Next()) {
    const uint16_t before = ray.band;
    const uint8_t n = bands_.material(c->band);
    ray.band = static_cast<uint16_t>(c->band);
    if (n != 0 && n != ray.material) {
      if (primary) {
        // The exact hit, kept in its cell (and near the slab) against
        // rounding. Its shadow ray starts right there, on the side the ray
        // came from (the lit side: Light turns the normal toward the
        // viewer), in the band it came from: the walk leaves that band only
        // by an edge's next root. Where the band was not a root's (the
        // ray's start, or after rounding), in the band found there.
        const Vec3 p = HitPoint(ray, walk.t(), walk.cell());
        const uint16_t light_band = c->root && before != RayDescriptor::kNoBand ? before : ray.band;
        const std::array<int32_t, 3> at = {FloorClamped(p.x, 0, dims[0] - 1),
                                           FloorClamped(p.y, y_begin, y_end - 1),
                                           FloorClamped(p.z, 0, dims[2] - 1)};
        if (!view) view = Normalize(-(ray.direction / inv_spacing_));
        finished = Shade(ray, n, p, *view, at, 0, light_band, bands_.material(light_band), spawned,
                         counters);
      } else {
        // A shadow ray dims by each material it enters.
        ray.transmittance *= 1.0f - materials[n - 1].opacity;
        if (ray.transmittance < settings_.min_transmittance) {
          ray.transmittance = 0;
          finished = true;
        }
      }
    }
    ray.material = n;
    if (finished) break;
  }
  counters.segments += walk.cells();
  counters.cells += walk.solved();
  if (walk.truncated()) {
    ++counters.truncated;
    return Outcome::kFinished;
  }
  if (finished || !leaves_slab) return Outcome::kFinished;
  // Nothing but its own band between the plane and the volume's face: the
  // walks on the other slabs would find nothing, and the ray ends here with
  // the deposit it would make there (field_summary.h).
  if (scene_.summary().Clear(ray.origin, axes, end, t_volume, ray.band)) {
    ++counters.ended_early;
    return Outcome::kFinished;
  }
  // Resumes on the neighbour at the plane: its walk begins in the cell this
  // one is in there.
  ray.t = end;
  const Vec3 p = ray.origin + ray.direction * end;
  ray.cell = {FloorClamped(p.x, 0, dims[0] - 1), axes.step[1] > 0 ? y_end : y_begin - 1,
              FloorClamped(p.z, 0, dims[2] - 1)};
  return Outcome::kLeftSlab;
}

Vec3 Tracer::HitPoint(const RayDescriptor& ray, double t, const std::array<int, 3>& cell) const {
  // In the cell of the field (c - 0.5 .. c + 0.5) and the volume, then
  // within a quarter voxel of the slab, whatever the cell: every plane a
  // gradient there reads is stored. A ray's walk keeps to cells of its
  // slab, but a hostile record can start one a cell past the slab's plane
  // (Validate allows a cell of rounding), and the gradient of a point
  // clamped into that cell read a plane past the slab's ghosts (found by
  // batch_fuzzer). Where the cell meets the slab, as for every ray a node
  // sends, the two clamps give the point the one clamp to both gave before.
  const auto& dims = scene_.dims();
  Vec3 p = ray.origin + ray.direction * t;
  for (int a = 0; a < 3; ++a) {
    const double lo = std::max(cell[a] - 0.5, 0.0), hi = std::min(cell[a] + 0.5, double(dims[a]));
    p[a] = std::max(lo, std::min(hi, p[a]));
  }
  p.y = std::clamp(p.y, scene_.y_begin() - 0.25, scene_.y_end() + 0.25);
  return p;
}

Tracer::Outcome Tracer::TraceSurfaces(RayDescriptor& ray, std::vector<RayDescriptor>& spawned,
                                      TraceCounters& counters) const {
  // The paper's voxel faces (smooth surfaces: TraceSmooth).
  Walker walker = MakeWalker(ray);
  const Vec3 view = Normalize(-(ray.direction / inv_spacing_));
  Outcome outcome;
  while (auto step = Walk(walker, &outcome, counters)) {
    const Segment& seg = step->seg;
    const std::array<int32_t, 3>& cell = step->cell;
    const uint8_t m = seg.material;
    if (m != 0 && m != ray.material) {
      // Start a voxel and a half toward the light: a shadow ray from the
      // face of a voxel-exact surface would otherwise hit the surface's own
      // staircase (shadow acne). The start cell may lie in another slab or
      // outside the volume; Trace then hands the ray on or finishes it.
      const Vec3 p = ClampToCell(ray.origin + ray.direction * seg.t0, cell);
      std::array<int32_t, 3> at;
      for (int a = 0; a < 3; ++a) {
        at[a] = static_cast<int32_t>(std::floor(p[a] + light_index_[a] * shadow_bias_));
      }
      const bool finished = Shade(ray, m, p, view, at, shadow_bias_, RayDescriptor::kNoBand, m,
                                  spawned, counters);
      ray.material = m;
      if (finished) return walker.Stop(ray, Outcome::kFinished);
    }
    ray.material = m;
  }
  return walker.Stop(ray, outcome);
}

Tracer::Outcome Tracer::TraceShadow(RayDescriptor& ray, TraceCounters& counters) const {
  const auto& materials = scene_.classification().materials;
  Walker walker = MakeWalker(ray);
  Outcome outcome;
  while (auto step = Walk(walker, &outcome, counters)) {
    const uint8_t m = step->seg.material;
    if (m != 0 && m != ray.material) {
      // Entering material m dims the ray; dark enough, it finishes.
      ray.transmittance *= 1.0f - materials[m - 1].opacity;
      ray.material = m;
      if (ray.transmittance < settings_.min_transmittance) {
        ray.transmittance = 0;
        return walker.Stop(ray, Outcome::kFinished);
      }
    }
    ray.material = m;
  }
  return walker.Stop(ray, outcome);
}

Tracer::Outcome Tracer::TraceDvr(RayDescriptor& ray, TraceCounters& counters) const {
  const TransferFunction& tf = scene_.transfer();
  Walker walker = MakeWalker(ray);
  const Vec3 view = Normalize(-(ray.direction / inv_spacing_));
  int64_t samples_left = max_samples_;
  Outcome outcome;
  while (auto step = Walk(walker, &outcome, counters)) {
    const Segment& seg = step->seg;
    const std::array<int32_t, 3>& cell = step->cell;
    if (seg.material == 0) continue;
    // k counts from the ray's entry; Validate keeps it, and t - t_start,
    // within the volume's diagonal, so these conversions are in range.
    const double k0 = std::floor((seg.t0 - ray.t_start) / step_);
    uint32_t k = std::max<uint32_t>(ray.sample, k0 > 0 ? static_cast<uint32_t>(k0) : 0);
    for (;; ++k) {
      if (--samples_left < 0) {
        ++counters.truncated;
        return walker.Stop(ray, Outcome::kFinished);
      }
      const double tk = ray.t_start + k * step_;
      if (tk >= seg.t1) break;
      if (tk < seg.t0) continue;
      // The sample's column is the segment's; keep it there against rounding.
      Vec3 p = ray.origin + ray.direction * tk;
      p.x = std::clamp(p.x, double(cell[0]), double(cell[0] + 1));
      p.y = std::clamp(p.y, double(cell[1]), double(cell[1] + 1));
      const TableEntry& e = Lookup(Sample(p));
      if (e.alpha <= 0) continue;
      ++counters.samples;
      if (counters.plane_work) counters.plane_work[cell[1] - walker.y_begin] += work_->sample;
      std::array<float, 3> rgb = e.color;
      if (tf.shading) {
        float diffuse, specular;
        Light(Gradient(p), view, &diffuse, &specular, tf.shininess);
        for (int c = 0; c < 3; ++c)
          rgb[c] = rgb[c] * (tf.ambient + tf.diffuse * diffuse) + tf.specular * specular;
      }
      const float w = ray.transmittance * e.alpha;
      for (int c = 0; c < 3; ++c) ray.color[c] += w * rgb[c];
      ray.transmittance *= 1.0f - e.alpha;
      if (ray.transmittance < settings_.min_transmittance) {
        ray.sample = k + 1;
        return walker.Stop(ray, Outcome::kFinished);
      }
    }
    ray.sample = k;
  }
  return walker.Stop(ray, outcome);
}

float Tracer::Sample(const Vec3& p) const {
  const double qx = p.x - 0.5, qy = p.y - 0.5, qz = p.z - 0.5;
  const int x0 = static_cast<int>(std::floor(qx)), y0 = static_cast<int>(std::floor(qy)),
            z0 = static_cast<int>(std::floor(qz));
  const float fx = static_cast<float>(qx - x0), fy = static_cast<float>(qy - y0),
              fz = static_cast<float>(qz - z0);
  auto lerp = [](float a, float b, float f) { return a + f * (b - a); };
  float c[8];  // corner x + 2y + 4z, clamped as Scalar does
  scene_.Corners(x0, y0, z0, c);
  const float c00 = lerp(c[0], c[1], fx), c10 = lerp(c[2], c[3], fx);
  const float c01 = lerp(c[4], c[5], fx), c11 = lerp(c[6], c[7], fx);
  return lerp(lerp(c00, c10, fy), lerp(c01, c11, fy), fz);
}

namespace {

// Central differences at the 8 voxels around a point, trilinearly weighted:
// `at(x, y, z)` reads a scalar. One sequence of operations whatever reads
// them, so the fast and the clamped path give the same bits.
template <typename At>
TRANSTICK_INLINE Vec3f WeightedDifferences(At at, int x0, int y0, int z0, const float f[3],
                                           float hx, float hy, float hz) {
  Vec3f g{0, 0, 0};
  for (int dz = 0; dz < 2; ++dz) {
    for (int dy = 0; dy < 2; ++dy) {
      for (int dx = 0; dx < 2; ++dx) {
        const int x = x0 + dx, y = y0 + dy, z = z0 + dz;
        const float w = (dx ? f[0] : 1 - f[0]) * (dy ? f[1] : 1 - f[1]) * (dz ? f[2] : 1 - f[2]);
        Vec3f c{(at(x + 1, y, z) - at(x - 1, y, z)) * hx, (at(x, y + 1, z) - at(x, y - 1, z)) * hy,
                (at(x, y, z + 1) - at(x, y, z - 1)) * hz};
        g += c * w;
      }
    }
  }
  return g;
}

#if defined(__SSE2__)
// WeightedDifferences on a 4^3 block of voxels read from `base` (voxel (x0,
// y0, z0); rows of `row` values, planes of `plane`), four corners at a time:
// for each plane of corners dz, the corners (dx, dy) in the order x + 2y
// in the four lanes, each axis's differences, scales and weights lane by
// lane, and then the products added to g one corner after another, in
// WeightedDifferences's order. Each lane rounds as the scalar code does, so
// the bits are the same.
TRANSTICK_INLINE Vec3f VectorDifferences(const float* base, ptrdiff_t row, ptrdiff_t plane,
                                         const float f[3], float hx, float hy, float hz) {
  auto pairs = [](const float* lo, const float* hi) {  // lo[0], lo[1], hi[0], hi[1]
    return _mm_loadh_pi(_mm_loadl_pi(_mm_setzero_ps(), reinterpret_cast<const __m64*>(lo)),
                        reinterpret_cast<const __m64*>(hi));
  };
  const __m128 one = _mm_set1_ps(1.0f);
  const __m128 fx = _mm_set1_ps(f[0]), fy = _mm_set1_ps(f[1]);
  // (dx ? f0 : 1 - f0) * (dy ? f1 : 1 - f1), lanes (dx, dy) = x + 2y.
  const __m128 wx = _mm_unpacklo_ps(_mm_sub_ps(one, fx), fx);
  const __m128 wy = _mm_shuffle_ps(_mm_sub_ps(one, fy), fy, _MM_SHUFFLE(0, 0, 0, 0));
  const __m128 wxy = _mm_mul_ps(wx, wy);
  const float wz[2] = {1 - f[2], f[2]};
  const __m128 h[3] = {_mm_set1_ps(hx), _mm_set1_ps(hy), _mm_set1_ps(hz)};
  __m128 g = _mm_setzero_ps();
  for (int dz = 0; dz < 2; ++dz) {
    const float* b = base + dz * plane;
    // x: voxels x0 - 1 .. x0 + 2 of rows y0 and y0 + 1.
    const __m128 u = _mm_loadu_ps(b - 1), v = _mm_loadu_ps(b + row - 1);
    const __m128 dx = _mm_sub_ps(_mm_shuffle_ps(u, v, _MM_SHUFFLE(3, 2, 3, 2)),
                                 _mm_shuffle_ps(u, v, _MM_SHUFFLE(1, 0, 1, 0)));
    const __m128 dy = _mm_sub_ps(pairs(b + row, b + 2 * row), pairs(b - row, b));
    const __m128 dzv =
        _mm_sub_ps(pairs(b + plane, b + plane + row), pairs(b - plane, b - plane + row));
    const __m128 w = _mm_mul_ps(wxy, _mm_set1_ps(wz[dz]));
    __m128 px = _mm_mul_ps(_mm_mul_ps(dx, h[0]), w);
    __m128 py = _mm_mul_ps(_mm_mul_ps(dy, h[1]), w);
    __m128 pz = _mm_mul_ps(_mm_mul_ps(dzv, h[2]), w);
    __m128 pw = _mm_setzero_ps();
    _MM_TRANSPOSE4_PS(px, py, pz, pw);  // now one corner a register: (x, y, z, 0)
    g = _mm_add_ps(g, px);
    g = _mm_add_ps(g, py);
    g = _mm_add_ps(g, pz);
    g = _mm_add_ps(g, pw);
  }
  alignas(16) float out[4];
  _mm_store_ps(out, g);
  return {out[0], out[1], out[2]};
}
#endif

}  // namespace

Vec3f Tracer::Gradient(const Vec3& p) const {
#if defined(__SSE2__)
  const double qx = p.x - 0.5, qy = p.y - 0.5, qz = p.z - 0.5;
  const int x0 = static_cast<int>(std::floor(qx)), y0 = static_cast<int>(std::floor(qy)),
            z0 = static_cast<int>(std::floor(qz));
  const Scene& s = scene_;
  const auto& dims = s.dims();
  // Away from the volume's faces and the slab's last stored planes the 4^3
  // voxels read need no clamping: addressed from one pointer.
  if (x0 >= 1 && x0 + 2 < dims[0] && z0 >= 1 && z0 + 2 < dims[2] && y0 - 1 >= s.scalar_y_begin() &&
      y0 + 2 < s.scalar_y_end()) {
    const float f[3] = {static_cast<float>(qx - x0), static_cast<float>(qy - y0),
                        static_cast<float>(qz - z0)};
    const ptrdiff_t row = dims[0];
    const ptrdiff_t plane = row * (s.scalar_y_end() - s.scalar_y_begin());
    const float* base = s.scalars().data() + z0 * plane + (y0 - s.scalar_y_begin()) * row + x0;
    return VectorDifferences(base, row, plane, f, static_cast<float>(0.5 * inv_spacing_.x),
                             static_cast<float>(0.5 * inv_spacing_.y),
                             static_cast<float>(0.5 * inv_spacing_.z));
  }
#endif
  return PortableGradient(p);
}

Vec3f Tracer::PortableGradient(const Vec3& p) const {
  const double qx = p.x - 0.5, qy = p.y - 0.5, qz = p.z - 0.5;
  const int x0 = static_cast<int>(std::floor(qx)), y0 = static_cast<int>(std::floor(qy)),
            z0 = static_cast<int>(std::floor(qz));
  const float f[3] = {static_cast<float>(qx - x0), static_cast<float>(qy - y0),
                      static_cast<float>(qz - z0)};
  const Scene& s = scene_;
  const float hx = static_cast<float>(0.5 * inv_spacing_.x),
              hy = static_cast<float>(0.5 * inv_spacing_.y),
              hz = static_cast<float>(0.5 * inv_spacing_.z);
  // Away from the volume's faces and the slab's last stored planes the 4^3
  // voxels read need no clamping: addressed from one pointer (the clamped
  // reads cost a shaded point about 1,700 instructions).
  const auto& dims = s.dims();
  if (x0 >= 1 && x0 + 2 < dims[0] && z0 >= 1 && z0 + 2 < dims[2] && y0 - 1 >= s.scalar_y_begin() &&
      y0 + 2 < s.scalar_y_end()) {
    const ptrdiff_t row = dims[0];
    const ptrdiff_t plane = row * (s.scalar_y_end() - s.scalar_y_begin());
    const float* base = s.scalars().data() + z0 * plane + (y0 - s.scalar_y_begin()) * row + x0;
    auto at = [&](int x, int y, int z) {
      return base[(z - z0) * plane + (y - y0) * row + (x - x0)];
    };
    return WeightedDifferences(at, x0, y0, z0, f, hx, hy, hz);
  }
  auto at = [&](int x, int y, int z) { return s.Scalar(x, y, z); };
  return WeightedDifferences(at, x0, y0, z0, f, hx, hy, hz);
}

const Tracer::TableEntry& Tracer::Lookup(float value) const {
  // Clamped before the conversion, which is undefined for NaN (a sample
  // next to a NaN voxel, or a value range wider than a float holds).
  const float x = (value - table_lo_) * table_scale_ + 0.5f;
  return table_[x >= kTableSize - 1 ? kTableSize - 1 : (x > 0 ? static_cast<int>(x) : 0)];
}

void Tracer::Light(const Vec3f& g, const Vec3& view_dir, float* diffuse, float* specular,
                   float shininess) const {
  const Vec3f view = ToFloat(view_dir);
  const Vec3f l = ToFloat(light_world_);
  // Surfaces face away from higher values; lit from either side.
  Vec3f n = Length(g) > 0 ? Normalize(-g) : view;
  if (Dot(n, view) < 0) n = -n;
  *diffuse = std::max(0.0f, Dot(n, l));
  const float nh = Dot(n, Normalize(l + view));
  *specular = (*diffuse > 0 && nh > 0) ? std::pow(nh, shininess) : 0.0f;
}

}  // namespace transtick

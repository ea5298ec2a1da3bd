#include "transtick/tracer.h"

#include <algorithm>
#include <cmath>

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

}  // namespace

Tracer::Tracer(const Scene& scene, const RenderSettings& settings, const Camera& camera)
    : scene_(scene), settings_(settings) {
  const auto& sp = scene.spacing();
  inv_spacing_ = {1.0 / sp[0], 1.0 / sp[1], 1.0 / sp[2]};
  Vec3 l = camera.right() * settings.light.x + camera.up() * settings.light.y -
           camera.forward() * settings.light.z;
  light_world_ = Normalize(l);
  if (Length(light_world_) == 0) light_world_ = -camera.forward();
  light_index_ = light_world_ * inv_spacing_;
  shadow_bias_ = 1.5 / Length(light_index_);
  step_ = settings.step > 0 ? settings.step : 0.5 * std::min({sp[0], sp[1], sp[2]});
  if (scene.mode() == RenderMode::kDvr) {
    const TransferFunction& tf = scene.transfer();
    const float lo = scene.value_range()[0], hi = scene.value_range()[1];
    table_.resize(kTableSize);
    table_lo_ = lo;
    table_scale_ = hi > lo ? (kTableSize - 1) / (hi - lo) : 0.0f;
    const double exponent = step_ / tf.reference_step;
    for (int i = 0; i < kTableSize; ++i) {
      float v = hi > lo ? lo + i * (hi - lo) / (kTableSize - 1) : lo;
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
  *ray = RayDescriptor{};
  ray->origin = o;
  ray->direction = d;
  ray->t = (*box)[0];
  ray->t_start = (*box)[0];
  ray->cell = CellAt(o, d, ray->t, dims);
  ray->pixel = pixel;
  ray->kind = RayKind::kPrimary;
  return true;
}

Deposit Tracer::MissDeposit(uint32_t pixel) const {
  return Deposit{pixel, RayKind::kPrimary, 0, settings_.background};
}

Tracer::Outcome Tracer::Trace(RayDescriptor& ray, std::vector<RayDescriptor>& spawned,
                              Deposit& deposit, TraceCounters& counters) const {
  Outcome outcome;
  if (ray.kind == RayKind::kShadow) {
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

// The loop shared by every kind of ray: stop when the ray leaves the volume
// (finished) or the slab (handed on), else take the next segment.
#define TRANSTICK_STEP_OR_RETURN(ray, trav, seg_cell, seg)                      \
  if (!Traversal::Inside(ray.cell, dims)) return Outcome::kFinished;            \
  if (ray.cell[1] < y_begin || ray.cell[1] >= y_end) return Outcome::kLeftSlab; \
  seg_cell = ray.cell;                                                          \
  seg = *trav.Next(ray.cell, ray.t);                                            \
  ++counters.segments

Tracer::Outcome Tracer::TraceSurfaces(RayDescriptor& ray, std::vector<RayDescriptor>& spawned,
                                      TraceCounters& counters) const {
  const auto& dims = scene_.dims();
  const int y_begin = scene_.y_begin(), y_end = scene_.y_end();
  const auto& materials = scene_.classification().materials;
  const Traversal trav(scene_, ray.origin, ray.direction);
  const Vec3 view = Normalize(-(ray.direction / inv_spacing_));
  std::array<int32_t, 3> cell;
  Segment seg;
  while (true) {
    TRANSTICK_STEP_OR_RETURN(ray, trav, cell, seg);
    const uint8_t m = seg.material;
    if (m != 0 && m != ray.material) {
      ++counters.surface_hits;
      const Material& mat = materials[m - 1];
      const Vec3 p = ClampToCell(ray.origin + ray.direction * seg.t0, cell);
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
        // Start a voxel and a half toward the light: a shadow ray from the
        // face of a voxel-exact surface would otherwise hit the surface's own
        // staircase (shadow acne). The start cell may lie in another slab or
        // outside the volume; Trace then hands the ray on or finishes it.
        s.origin = p;
        s.direction = light_index_;
        s.t = shadow_bias_;
        s.t_start = 0;
        for (int a = 0; a < 3; ++a) {
          s.cell[a] = static_cast<int32_t>(std::floor(p[a] + light_index_[a] * shadow_bias_));
        }
        s.pixel = ray.pixel;
        s.kind = RayKind::kShadow;
        s.material = m;
        s.color = direct;
        s.transmittance = 1;
        spawned.push_back(s);
        ++ray.spawned;
        ++counters.shadow;
      } else if (lit) {
        for (int c = 0; c < 3; ++c) ray.color[c] += direct[c];
      }
      ray.transmittance *= 1.0f - mat.opacity;
      if (ray.transmittance < settings_.min_transmittance) {
        ray.material = m;
        return Outcome::kFinished;
      }
    }
    ray.material = m;
  }
}

Tracer::Outcome Tracer::TraceShadow(RayDescriptor& ray, TraceCounters& counters) const {
  const auto& dims = scene_.dims();
  const int y_begin = scene_.y_begin(), y_end = scene_.y_end();
  const auto& materials = scene_.classification().materials;
  const Traversal trav(scene_, ray.origin, ray.direction);
  std::array<int32_t, 3> cell;
  Segment seg;
  while (true) {
    TRANSTICK_STEP_OR_RETURN(ray, trav, cell, seg);
    const uint8_t m = seg.material;
    if (m != 0 && m != ray.material) {
      ray.transmittance *= 1.0f - materials[m - 1].opacity;
      if (ray.transmittance < settings_.min_transmittance) {
        ray.transmittance = 0;
        ray.material = m;
        return Outcome::kFinished;
      }
    }
    ray.material = m;
  }
}

Tracer::Outcome Tracer::TraceDvr(RayDescriptor& ray, TraceCounters& counters) const {
  const auto& dims = scene_.dims();
  const int y_begin = scene_.y_begin(), y_end = scene_.y_end();
  const TransferFunction& tf = scene_.transfer();
  const Traversal trav(scene_, ray.origin, ray.direction);
  const Vec3 view = Normalize(-(ray.direction / inv_spacing_));
  std::array<int32_t, 3> cell;
  Segment seg;
  while (true) {
    TRANSTICK_STEP_OR_RETURN(ray, trav, cell, seg);
    if (seg.material == 0) continue;
    double k0 = std::floor((seg.t0 - ray.t_start) / step_);
    uint32_t k = std::max<uint32_t>(ray.sample, k0 > 0 ? static_cast<uint32_t>(k0) : 0);
    for (;; ++k) {
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
        return Outcome::kFinished;
      }
    }
    ray.sample = k;
  }
}

#undef TRANSTICK_STEP_OR_RETURN

float Tracer::Sample(const Vec3& p) const {
  const double qx = p.x - 0.5, qy = p.y - 0.5, qz = p.z - 0.5;
  const int x0 = static_cast<int>(std::floor(qx)), y0 = static_cast<int>(std::floor(qy)),
            z0 = static_cast<int>(std::floor(qz));
  const float fx = static_cast<float>(qx - x0), fy = static_cast<float>(qy - y0),
              fz = static_cast<float>(qz - z0);
  auto lerp = [](float a, float b, float f) { return a + f * (b - a); };
  const Scene& s = scene_;
  float c00 = lerp(s.Scalar(x0, y0, z0), s.Scalar(x0 + 1, y0, z0), fx);
  float c10 = lerp(s.Scalar(x0, y0 + 1, z0), s.Scalar(x0 + 1, y0 + 1, z0), fx);
  float c01 = lerp(s.Scalar(x0, y0, z0 + 1), s.Scalar(x0 + 1, y0, z0 + 1), fx);
  float c11 = lerp(s.Scalar(x0, y0 + 1, z0 + 1), s.Scalar(x0 + 1, y0 + 1, z0 + 1), fx);
  return lerp(lerp(c00, c10, fy), lerp(c01, c11, fy), fz);
}

Vec3f Tracer::Gradient(const Vec3& p) const {
  const double qx = p.x - 0.5, qy = p.y - 0.5, qz = p.z - 0.5;
  const int x0 = static_cast<int>(std::floor(qx)), y0 = static_cast<int>(std::floor(qy)),
            z0 = static_cast<int>(std::floor(qz));
  const float f[3] = {static_cast<float>(qx - x0), static_cast<float>(qy - y0),
                      static_cast<float>(qz - z0)};
  const Scene& s = scene_;
  const float hx = static_cast<float>(0.5 * inv_spacing_.x),
              hy = static_cast<float>(0.5 * inv_spacing_.y),
              hz = static_cast<float>(0.5 * inv_spacing_.z);
  Vec3f g{0, 0, 0};
  for (int dz = 0; dz < 2; ++dz) {
    for (int dy = 0; dy < 2; ++dy) {
      for (int dx = 0; dx < 2; ++dx) {
        const int x = x0 + dx, y = y0 + dy, z = z0 + dz;
        const float w = (dx ? f[0] : 1 - f[0]) * (dy ? f[1] : 1 - f[1]) * (dz ? f[2] : 1 - f[2]);
        Vec3f c{(s.Scalar(x + 1, y, z) - s.Scalar(x - 1, y, z)) * hx,
                (s.Scalar(x, y + 1, z) - s.Scalar(x, y - 1, z)) * hy,
                (s.Scalar(x, y, z + 1) - s.Scalar(x, y, z - 1)) * hz};
        g += c * w;
      }
    }
  }
  return g;
}

const Tracer::TableEntry& Tracer::Lookup(float value) const {
  int i = static_cast<int>((value - table_lo_) * table_scale_ + 0.5f);
  return table_[std::clamp(i, 0, kTableSize - 1)];
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

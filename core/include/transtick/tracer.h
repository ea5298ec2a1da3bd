// The tracer: advances ray descriptors through a scene (a slab, or the whole
// volume), shading surfaces (the paper's threshold surfaces, with
// transparency and shadow rays) or compositing samples (dvr).
#ifndef TRANSTICK_TRACER_H_
#define TRANSTICK_TRACER_H_

#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include "absl/status/status.h"
#include "transtick/camera.h"
#include "transtick/classification.h"
#include "transtick/isosurface.h"
#include "transtick/ray.h"
#include "transtick/scene.h"
#include "transtick/traversal.h"

namespace transtick {

struct RenderSettings {
  bool shadows = true;  // surfaces mode only
  std::array<float, 3> background = {0, 0, 0};
  double step = 0;  // dvr sample step in world units; 0 = half the smallest spacing
  // Rays stop once their transmittance falls below this.
  float min_transmittance = 1.0f / 1024.0f;
  // Direction toward the (directional) light in world space, camera-relative:
  // x along the camera's right, y along its up, z toward the viewer.
  Vec3 light = {-0.35, 0.5, 1.0};
  // Primary rays per pixel, at SampleOffset's pattern (camera.h), in
  // [1, kMaxSamplesPerPixel]; the pixel is their mean.
  int samples = 1;
};

// Counts a tracer adds to; one per thread, summed afterwards.
struct TraceCounters {
  uint64_t primary = 0;       // primary rays generated that enter the volume
  uint64_t shadow = 0;        // shadow rays spawned
  uint64_t segments = 0;      // traversal steps taken
  uint64_t surface_hits = 0;  // shaded surface points (surfaces mode)
  uint64_t cells = 0;         // smooth surfaces: cells of the field whose corners were read
  uint64_t samples = 0;       // shaded samples (dvr)
  // Pixel samples whose rays were not made, known to meet nothing
  // (Tracer::Void): counted where pixels are traced in process (TraceRows).
  uint64_t void_rays = 0;
  // Smooth surfaces: rays that ended at their slab's plane, the field
  // summary showing nothing but their band up to the volume's face.
  uint64_t ended_early = 0;
  // Rays finished early at the hard per-call bound on steps or samples
  // (Tracer::Trace). The termination argument says this never happens; a
  // non-zero count is a defect, reported in the frame's statistics.
  uint64_t truncated = 0;
  // When set, the work done in each plane of the tracer's slab (docs/
  // balancing.md, "The work profile"): plane_work[y - y_begin] for plane y,
  // in the units of the tracer's WorkWeights. The caller owns the array
  // (one entry per plane of the slab); Add leaves it alone.
  uint64_t* plane_work = nullptr;
  void Add(const TraceCounters& o) {
    primary += o.primary;
    shadow += o.shadow;
    segments += o.segments;
    surface_hits += o.surface_hits;
    cells += o.cells;
    samples += o.samples;
    void_rays += o.void_rays;
    ended_early += o.ended_early;
    truncated += o.truncated;
  }
};

// What the work profile (TraceCounters::plane_work) counts, in units of
// about 5 ns of a worker's tracer CPU, fitted to measured slabs (docs/
// balancing.md, "The work profile"; bench/cluster_bench weights): a step
// of the walk (a traversal segment, or a cell or box of the field's walk),
// a cell of the field whose corners are read, a shaded point (gradient,
// light, its shadow ray), a dvr sample, and what a ray costs a node apart
// from its steps (taking it, its deposit or its hand-over; a miss's deposit
// too). The models differ in what a step is, so each has its own.
struct WorkWeights {
  uint64_t step;
  uint64_t cell;
  uint64_t hit;
  uint64_t sample;
  uint64_t ray;
};
// The paper's voxel surfaces and dvr, over the traversal's segments.
inline constexpr WorkWeights kTraversalWork = {12, 0, 72, 10, 18};
// Smooth surfaces, over the field's cells. (Fitted to slabs' CPU alone,
// a ray would weigh 50 and a step 3; but a ray's fixed cost is counted on
// the plane where a slab takes it, and weighed that much it crowds the
// profile at the slabs' edges: the cuts came out worse. docs/balancing.md.)
inline constexpr WorkWeights kFieldWork = {12, 24, 72, 0, 18};

// Limits that keep every frame finite (docs/design.md, "Why every ray ends").
// The finest dvr step: this many samples per voxel along the smallest
// spacing.
inline constexpr double kMaxSamplesPerVoxel = 32;
// The most dvr samples a frame may take, estimated as pixels times the
// samples of the longest ray through the volume (2^36: about 10 minutes on
// two cores).
inline constexpr double kMaxFrameSamples = 68719476736.0;

// Checks settings against the volume they will render, before any ray is
// traced: samples per pixel in [1, kMaxSamplesPerPixel], the dvr step (finite, not below 1/kMaxSamplesPerVoxel of the
// smallest spacing) and the frame's estimated samples (at most
// kMaxFrameSamples). Errors say what to change.
absl::Status CheckRenderSettings(const RenderSettings& settings, RenderMode mode,
                                 const std::array<int, 3>& dims,
                                 const std::array<double, 3>& spacing, int64_t pixels);

// Immutable after construction, thread-safe: many threads call Trace at once
// with their own descriptors, outputs and counters.
class Tracer {
 public:
  // REQUIRES: the scene outlives the tracer.
  Tracer(const Scene& scene, const RenderSettings& settings, const Camera& camera);

  // The primary ray of `pixel` in index space. Returns false when the ray
  // misses the volume; its pixel then gets `MissDeposit`.
  bool MakePrimary(const WorldRay& world, uint32_t pixel, RayDescriptor* ray) const;
  Deposit MissDeposit(uint32_t pixel) const;
  // Whether the rays of pixel (col, row) of the camera's image are known
  // to meet nothing before they are made: with smooth surfaces, when band 0
  // has no material and the field summary shows that they cross only
  // bricks of band 0 (FieldSummary::PixelsMeeting). The pixel then gets
  // MissDeposit, bit for bit the deposit their walks would leave.
  bool Void(int col, int row) const {
    return !meets_.empty() && static_cast<unsigned>(col) < static_cast<unsigned>(meets_.width()) &&
           static_cast<unsigned>(row) < static_cast<unsigned>(meets_.height()) &&
           !meets_.Get(col, row);
  }

  enum class Outcome { kFinished, kLeftSlab };

  // Whether a descriptor that came from elsewhere (a neighbour's stream) is
  // one this tracer could have made: finite numbers, a unit world
  // direction, a cell inside the volume near the point at t, t after
  // t_start and within the volume's diagonal of it, a sample index and
  // material in range, transmittance in [0, 1], and a shadow ray only in
  // surfaces mode with shadows on. A ray that passes finishes
  // within the bounds below; one that fails is named by the error.
  absl::Status Validate(const RayDescriptor& ray) const;

  // Advances `ray` while its cell lies in the scene's slab. On kFinished,
  // `deposit` holds what the ray leaves in its pixel; on kLeftSlab the
  // descriptor is ready to resume on the node owning ray.cell[1]. Shadow rays
  // spawned are appended to `spawned` (they start in this slab).
  // Each call takes at most max_segments() traversal steps and, in dvr,
  // max_samples() sample positions; a ray that reaches either bound is
  // finished and counted in counters.truncated, never looped.
  Outcome Trace(RayDescriptor& ray, std::vector<RayDescriptor>& spawned, Deposit& deposit,
                TraceCounters& counters) const;

  double step() const { return step_; }
  // The weights of the work profile for this tracer's model.
  const WorkWeights& work_weights() const { return *work_; }
  int64_t max_segments() const { return max_segments_; }
  int64_t max_samples() const { return max_samples_; }

  // World-space gradient at an index-space point, trilinearly interpolated
  // from central differences at the 8 nearest voxel centres.
  // REQUIRES: the planes the differences read are stored (a shading point
  // of the slab, HitPoint's).
  Vec3f Gradient(const Vec3& p) const;
  // The same, one voxel at a time in plain float arithmetic, without the
  // vector instructions Gradient may use: bit for bit the same. For tests.
  Vec3f PortableGradient(const Vec3& p) const;

 private:
  struct TableEntry {
    std::array<float, 3> color;
    float alpha;
  };

  // A segment of the walk and the cell it lies in.
  struct Step {
    Segment seg;
    std::array<int32_t, 3> cell;
  };
  // One ray's walk: the traversal, which owns the ray's cell and t while
  // it runs, and the scene's bounds copied to the stack (loaded through the
  // scene at every step they cost a reload each time a counter is
  // written). Made on the stack of each Trace* function, so that its
  // state can stay in registers.
  struct Walker {
    Traversal trav;
    std::array<int, 3> dims;
    int y_begin, y_end;
    int64_t steps_left;
    uint64_t step_work;  // work profile units per step
    // Writes where the walk is back into the descriptor, which then
    // resumes there (kLeftSlab), and returns `outcome`.
    Outcome Stop(RayDescriptor& ray, Outcome outcome) const {
      ray.cell = trav.cell();
      ray.t = trav.t();
      return outcome;
    }
  };
  Walker MakeWalker(const RayDescriptor& ray) const {
    return {Traversal(scene_, ray), scene_.dims(), scene_.y_begin(), scene_.y_end(), max_segments_,
            work_->step};
  }
  // The step every kind of ray takes next: the next segment, or nullopt
  // with *outcome set, finished (the ray left the volume, or reached the
  // bound w.steps_left counts down) or left the slab.
  static std::optional<Step> Walk(Walker& w, Outcome* outcome, TraceCounters& counters);

  // The paper's voxel surfaces: primary rays (TraceSurfaces) and shadow
  // rays (TraceShadow) over the traversal's segments.
  Outcome TraceSurfaces(RayDescriptor& ray, std::vector<RayDescriptor>& spawned,
                        TraceCounters& counters) const;
  // Shades the surface of material m that `ray` meets at point p (index
  // space) and spawns its shadow ray, which starts at (shadow_cell,
  // shadow_t) on the line p + t * light, in `shadow_band` with material
  // `shadow_material`. Returns true when the ray has become opaque enough
  // to finish.
  bool Shade(RayDescriptor& ray, uint8_t m, const Vec3& p, const Vec3& view,
             const std::array<int32_t, 3>& shadow_cell, double shadow_t, uint16_t shadow_band,
             uint8_t shadow_material, std::vector<RayDescriptor>& spawned,
             TraceCounters& counters) const;
  // Smooth surfaces, primary and shadow rays alike: one CrossingWalk over
  // the field's cells from ray.t to where the ray leaves the slab or the
  // volume (docs/design.md, "Smooth surfaces").
  Outcome TraceSmooth(RayDescriptor& ray, std::vector<RayDescriptor>& spawned,
                      TraceCounters& counters) const;
  // Where a smooth surface is shaded: the point at t kept in the field's
  // cell `cell`, in the volume, and within a quarter voxel of the slab.
  Vec3 HitPoint(const RayDescriptor& ray, double t, const std::array<int, 3>& cell) const;
  Outcome TraceShadow(RayDescriptor& ray, TraceCounters& counters) const;
  Outcome TraceDvr(RayDescriptor& ray, TraceCounters& counters) const;

  float Sample(const Vec3& p) const;  // trilinear, cell-centred
  const TableEntry& Lookup(float value) const;
  // Diffuse and specular terms at a point with (unnormalised) gradient g.
  void Light(const Vec3f& g, const Vec3& view_dir_world, float* diffuse, float* specular,
             float shininess) const;

  const Scene& scene_;
  RenderSettings settings_;
  bool smooth_ = false;  // smooth surfaces (SurfaceModel::kSmooth)
  const WorkWeights* work_ = &kTraversalWork;
  Bands bands_;
  Vec3 light_world_;        // unit, toward the light
  Vec3 light_index_;        // light_world_ / spacing
  double shadow_bias_ = 0;  // t at which shadow rays start: 1.5 voxels out
  Vec3 inv_spacing_;
  double step_ = 1;
  double diagonal_ = 0;  // world length of the volume's diagonal
  int64_t max_segments_ = 0;
  int64_t max_samples_ = 0;
  PixelMask meets_;  // Void's pixels left clear; empty: none known
  // dvr: colour and step-corrected opacity for values across value_range.
  static constexpr int kTableSize = 4096;
  std::vector<TableEntry> table_;
  float table_lo_ = 0, table_scale_ = 0;
};

}  // namespace transtick

#endif  // TRANSTICK_TRACER_H_
